"""Figures of the paper: each draws one artifact and checks its paper claims from given tables.

The figure layer: one module per artifact, named after it (``fig01_pipeline`` …
``fig13_ar_hmm``, ``gap_benchmark``, as the rule, the script and the files in
``paper_figures/``). Each module takes the tables and JSON the stage rules wrote (and the
authors' R numbers, already loaded) and returns a :class:`dtwin.artifacts.FigureArtifact`: the
matplotlib figure, the metrics and the :class:`dtwin.artifacts.Check` list. Figure code fits no
model and reads no file: crosschecks against the R code are computed by the stage rules (the
``dtwin.reference.*_crosscheck`` modules) and arrive here as finished results. A claim's
criterion is a public function of :mod:`dtwin.claim_criteria` or
:mod:`dtwin.fault_claim_criteria`, which the claims across random draws call too; Fig. 11's
sweep claims live in the ``_fig11_claims`` companion module.

Keeping one module per figure means a change to one figure's code reruns only that figure's
rule (and ``claims``); :mod:`dtwin.figures._style` holds the shared look and the deterministic,
atomic saver.
"""
