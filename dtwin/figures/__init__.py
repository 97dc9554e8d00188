"""Figures of the paper: each draws one artifact and checks its paper claims from given tables.

The figure layer: one module per paper artifact, named after it (``fig01_pipeline`` …
``fig11_sensitivity``, as the rule, the script and the files in ``paper_figures/``). Each
module takes the tables and JSON the stage rules wrote (and the authors' R numbers, already
loaded) and returns a :class:`dtwin.artifacts.FigureArtifact`: the matplotlib figure, the
metrics and the :class:`dtwin.artifacts.Check` list. Figure code fits no model and reads no
file: crosschecks against the R code are computed by the stage rules
(:mod:`dtwin.reference.crosschecks`) and arrive here as finished results. Modules that mix a
large drawing with much claim logic keep the claims in a ``_claims`` companion module.

Keeping one module per figure means a change to one figure's code reruns only that figure's
rule; :mod:`dtwin.figures._style` holds the shared look and the deterministic, atomic saver.
"""
