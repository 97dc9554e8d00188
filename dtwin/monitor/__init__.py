"""The paper's regime method on a user's twin: ``dtwin regimes`` on a recording, ``dtwin monitor``.

Specification: docs/monitor.md. The twin table's units are frozen and run causally
(:mod:`dtwin.monitor.causal_twin`), their residuals filtered by the regime HMM with an
``unknown`` regime (:mod:`dtwin.monitor.regime_model`, :mod:`dtwin.monitor.regime_tracker`), the
twin's outputs corrected and an action chosen per regime (:mod:`dtwin.monitor.action_table`).
``dtwin regimes`` fits the model on a recording (:mod:`dtwin.monitor.batch_regimes`, written by
:mod:`dtwin.monitor.regimes_report` and :mod:`dtwin.monitor.model_file`); ``dtwin monitor`` runs
the same code over a live stream (:mod:`dtwin.monitor.row_stream`, :mod:`dtwin.monitor.live`,
background diagnoses :mod:`dtwin.monitor.background`). :mod:`dtwin.monitor.commands` holds both
commands' arguments; only the command line imports this package. Arrays are time-first:
``(n_samples,)`` or ``(n_samples, n_channels)``; nothing is re-exported here (import from the
submodules).
"""
