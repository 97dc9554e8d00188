"""The twin as data: a module table a user writes, its blocks, expressions and simulation.

Specification: docs/gap.md §Twin file. The package is the bottom layer that the diagnoser
(:mod:`dtwin.gap`), the benchmark (:mod:`dtwin.gapbench`) and the monitor read; it imports
numpy, scipy (lazily), numba (lazily, through :mod:`dtwin._jit`) and the helpers only.

- :mod:`dtwin.twin.expressions`: a user's equation text → a whitelisted postfix program;
  nothing is ever ``eval``-ed.
- :mod:`dtwin.twin.table`: the ``modules:`` table → :class:`~dtwin.twin.table.TwinTable`,
  every bad entry refused with one line naming the module, the key and the token.
- :mod:`dtwin.twin.blocks`: the built-in blocks (``lag``, ``mass_spring_damper``,
  ``integrator``, ``gain``, ``weighted_sum``, ``state_space``) lowered to equations.
- :mod:`dtwin.twin.simulate`: a unit of modules (one module, or modules joined by unrecorded
  signals) integrated over windows that restart from the recording.
- the paper's six modules: :mod:`dtwin.twin.wiring` (the wiring table and roles),
  :mod:`dtwin.twin.paper_modules` (their contract and laws), :mod:`dtwin.twin.exact` (the plant
  discretised exactly for any hold) and :mod:`dtwin.twin._force_kernels` (its compiled loops).

Arrays are time-first: ``(n_samples,)`` or ``(n_samples, n_channels)``.
"""
