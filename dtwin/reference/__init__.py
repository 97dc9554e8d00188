"""Everything about the authors' R code: its column names, loaders of its outputs, crosschecks.

- :mod:`dtwin.reference.columns`: R's column names and labels → ours (the one place they live);
- :mod:`dtwin.reference.loaders`: read ``config/reference/*.csv`` in our names;
- crosschecks, one module per concept checked, each running our code on R's own signals or
  tables and comparing with R: :mod:`~dtwin.reference.arx_crosscheck` (ARX fit and rollout),
  :mod:`~dtwin.reference.em_crosscheck` (EM log-likelihood vs depmixS4),
  :mod:`~dtwin.reference.hungarian_crosscheck` (regime matching and scores),
  :mod:`~dtwin.reference.correction_crosscheck` (targeted intervention),
  :mod:`~dtwin.reference.mcda_crosscheck` (TOPSIS legacy mode vs RMCDA 0.3.1) and
  :mod:`~dtwin.reference.bic_crosscheck` (the BIC formula);
- :mod:`dtwin.reference.crosscheck_result`: a crosscheck's result and its JSON file.

Crosschecks that fit a model run in the stage rule of the concept they check and write
``results/**/…crosscheck.json``; the figures read the finished result (see
:mod:`dtwin.figures`). One module per crosscheck keeps each stage rule's library inputs (and
so its reruns) to what it checks. The R code's notes are ``config/reference/r_notes.md``.
Import names from the submodules: the package re-exports nothing, so a light rule that
imports a loader does not import the crosschecks' dependencies (hmmlearn, scipy.signal).
"""
