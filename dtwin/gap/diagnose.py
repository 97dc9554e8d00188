"""The sim-to-real gap diagnoser: where the gap lies, which effect causes it, how far it shrinks.

:func:`diagnose` implements docs/gap.md in three steps, one module each:

1. **Where** (:mod:`dtwin.gap.where`, §Where): each recorded module's twin, noise floor, gap
   and threshold, on the training and choosing parts; the *source* is the module furthest above
   its threshold.
2. **Which** (:mod:`dtwin.gap.which`, §Which): the candidates of each module with a gap fitted
   on the training part and scored on the **choosing part**; ``unexplained`` when the best
   removes too little, ``none`` when no module has a gap.
3. **How far** (:mod:`dtwin.gap.how_far`, §How far): the shrinks, the chain's KPI, the free run
   and the intervals of the answer on the **scoring part**.

Every decision is taken before the scoring part (where the gap lies: training and choosing
parts; which candidate and ``unexplained``: the choosing part); every reported shrink on the
scoring part (docs/gap.md §Interface). The settings and results are
:mod:`dtwin.gap.results`', the twin file's parsing :mod:`dtwin.gap.twin_file`'s.
"""

from __future__ import annotations

import logging

import numpy as np
from threadpoolctl import threadpool_limits

from dtwin._validation import DtwinTypeError, DtwinValueError, require_in_range
from dtwin.gap.closed_loop import causal_holds
from dtwin.gap.effects import effects_for_module
from dtwin.gap.how_far import (
    answer_intervals,
    chain_before_after,
    chain_kpi_shrink,
    free_run_rms,
    module_reports,
    scoring_series,
    verdict,
)
from dtwin.gap.recording import Recording, diagnosable_modules
from dtwin.gap.results import Diagnosis, GapSettings
from dtwin.gap.where import (
    Layout,
    Split,
    add_reference_gaps,
    analyse_module,
    check_inputs_vary,
    module_notes,
)
from dtwin.gap.which import choose, fit_candidates, nested_test, other_gaps, score_candidates
from dtwin.params import TwinParams
from dtwin.twin.exact import EXACT_HOLDS
from dtwin.twin.paper_modules import EULER
from dtwin.twin.wiring import MODULES

__all__ = ["DT_TOLERANCE", "MIN_TRAIN_SAMPLES", "MIN_PART_SAMPLES", "join_heldout", "diagnose"]

#: The diagnoser's steps, at INFO (``dtwin diagnose`` shows the current one on stderr once a
#: run has taken a few seconds: docs/gap.md §Speed).
progress = logging.getLogger(f"{__name__}.progress")


#: Largest relative disagreement between the recording's dt and ``twin.dt``.
DT_TOLERANCE = 0.01


#: Fewest samples of the training part, and of the choosing and the scoring part.
MIN_TRAIN_SAMPLES, MIN_PART_SAMPLES = 100, 50


def _check_arguments(recording, twin, train_frac, heldout, choose_frac) -> tuple:
    """Validate the arguments of :func:`diagnose`; return ``(train_frac, n_train, n_choose)``.

    ``n_train`` samples from the start are the training part; the choosing part ends at
    ``n_choose`` (the ``choose_frac`` share of the rest; with a separate held-out recording,
    the whole rest of the recording: the held-out recording is the scoring part)
    (docs/gap.md §Interface).
    """
    if not isinstance(recording, Recording):
        raise DtwinTypeError(f"recording must be a Recording (got {type(recording).__name__})")
    if not isinstance(twin, TwinParams):
        raise DtwinTypeError(f"twin must be TwinParams (got {type(twin).__name__})")
    if heldout is not None and not isinstance(heldout, Recording):
        raise DtwinTypeError(f"heldout must be a Recording (got {type(heldout).__name__})")
    train_frac = require_in_range("train_frac", train_frac, 0.05, 0.95)
    for label, rec in (("recording", recording), ("held-out recording", heldout)):
        if rec is not None and abs(rec.dt - twin.dt) > DT_TOLERANCE * twin.dt:
            raise DtwinValueError(
                f"{label} dt ({rec.dt:.6g} s, from column 't') disagrees with twin.dt "
                f"({twin.dt:.6g} s) by more than {DT_TOLERANCE:.0%}"
            )
    n = recording.n_samples
    n_train = int(round(train_frac * n))
    if heldout is not None:
        n_choose, n_score = n - n_train, heldout.n_samples
    else:
        n_choose = int(round(choose_frac * (n - n_train)))
        n_score = n - n_train - n_choose
    if n_train < MIN_TRAIN_SAMPLES or min(n_choose, n_score) < MIN_PART_SAMPLES:
        raise DtwinValueError(
            f"train_frac must leave at least {MIN_TRAIN_SAMPLES} samples for training and "
            f"{MIN_PART_SAMPLES} each for choosing and for scoring (got {n_train}, {n_choose} "
            f"and {n_score}{'; the scoring part is the held-out recording' if heldout else ''})"
        )
    return train_frac, n_train, n_train + n_choose


def join_heldout(
    recording: Recording, n_train: int, heldout: Recording, names: list[str]
) -> Recording:
    """Return the first ``n_train`` samples of ``recording`` followed by the held-out recording.

    :func:`diagnose` keeps the whole first recording (its training and choosing parts); the
    held-out recording is the scoring part.

    Parameters
    ----------
    recording : Recording
        The first experiment; its first ``n_train`` samples are kept.
    n_train : int
        Number of samples kept.
    heldout : Recording
        The validation experiment; it must record every signal of the diagnosed ``names``.
    names : list of str
        The modules diagnosed on ``recording``.

    Returns
    -------
    Recording
        Shape ``(n_train + heldout.n_samples,)`` per signal; the held-out time continues the
        training time by one ``dt``. Every model restarts from the recorded state at sample
        ``n_train`` (a new experiment).
    """
    needed = sorted(
        {s for m in MODULES if m.name in names for s in (*m.inputs, m.output)}
        & set(recording.signals)
    )
    missing = [s for s in needed if s not in heldout.signals]
    if missing:
        raise DtwinValueError(
            f"held-out recording is missing column(s) {', '.join(missing)} "
            f"(the training recording has: {', '.join(needed)})"
        )
    t_held = recording.t[n_train - 1] + recording.dt + (heldout.t - heldout.t[0])
    signals = {
        s: np.concatenate([recording.signals[s][:n_train], heldout.signals[s]]) for s in needed
    }
    return Recording(
        t=np.concatenate([recording.t[:n_train], t_held]),
        dt=recording.dt,
        signals=signals,
        ignored=recording.ignored,
        time_resolution=recording.time_resolution,
    )


def diagnose(
    recording: Recording,
    twin: TwinParams,
    *,
    calibrate: bool = False,
    train_frac: float = 0.5,
    settings: GapSettings | None = None,
    discretisation: str | None = None,
    heldout: Recording | None = None,
) -> Diagnosis:
    """Diagnose the sim-to-real gap of a recording against a twin.

    Parameters
    ----------
    recording : Recording
        The validated recording (:func:`dtwin.gap.recording.read_recording`).
    twin : TwinParams
        The twin (:func:`twin_from_mapping`); sections may be None (calibrated from data).
    calibrate : bool, default False
        Fit every diagnosed module's linear twin on the training part first.
    train_frac : float, default 0.5
        Fraction of samples, from the start, used for fitting (the training part); of the
        rest, the first ``settings.choose_frac`` is the choosing part (every decision), the
        remainder the scoring part (every reported gap after an effect and every shrink).
    settings : GapSettings, optional
        Decision constants.
    discretisation : {"euler", "zoh", "foh", "bandlimited"}, optional
        The plant's discretisation; default ``twin.discretisation`` (the twin file's). When
        both are None, the one of the four whose linear twin fits the training part best
        (``Diagnosis.twin_discretisation`` is then None, ``modules["M1"].discretisation``
        the one used).
    heldout : Recording, optional
        A separate validation experiment: the scoring part. The first ``round(train_frac·n)``
        samples of ``recording`` are the training part, the rest of it the choosing part.

    Returns
    -------
    Diagnosis

    Raises
    ------
    DtwinValueError
        If ``twin.dt`` disagrees with the recording's by more than 1 %, the split leaves fewer
        than 100 training samples or fewer than 50 for choosing or for scoring, or a module
        input is constant.

    Notes
    -----
    The three steps (where, which, how far) are specified in docs/gap.md §Where, §Which and
    §How far. BLAS runs single-threaded here: the diagnoser's matrices are 2×2 to 4×4, for
    which threads cost more than 100× the arithmetic on a loaded machine.
    """
    with threadpool_limits(limits=1):
        return _diagnose(recording, twin, calibrate, train_frac, settings, discretisation, heldout)


def _diagnose(recording, twin, calibrate, train_frac, settings, discretisation, heldout):
    """Run :func:`diagnose` (same arguments) with the thread limit set."""
    settings = settings or GapSettings()
    train_frac, n_train, n_choose = _check_arguments(
        recording, twin, train_frac, heldout, settings.choose_frac
    )
    discretisation = discretisation or twin.discretisation
    holds = (EULER, *EXACT_HOLDS) if discretisation is None else (discretisation,)
    names = diagnosable_modules(recording.signals)
    check_inputs_vary(recording, names, n_train)
    holds, loop_notes = causal_holds(recording.signals, names, holds, n_train)
    layout = Layout(holds)
    if heldout is not None:
        recording = join_heldout(recording, n_choose, heldout, names)
        layout = Layout(holds, (n_choose,))
    n = recording.n_samples
    split = Split(n_train, n_choose, n)
    t = recording.t - recording.t[0]
    notes: list[str] = list(loop_notes)
    if recording.ignored:
        notes.append(f"ignored columns that are not module signals: {', '.join(recording.ignored)}")

    works = {}
    for name in names:
        progress.info("%s: linear twin and noise floor (%d samples)", name, n)
        works[name] = analyse_module(name, recording, twin, t, split, calibrate, settings, layout)
    add_reference_gaps(works, split)
    notes.extend(module_notes(works, calibrate))
    flagged = [w for w in works.values() if w.gap_cal > w.threshold]
    for work in flagged:
        progress.info("%s: fitting the candidate effects", work.name)
        fit_candidates(work, split)
    for work in works.values():
        if (
            (work.calibrated or work.floor.process > 0.0)
            and work not in flagged
            and effects_for_module(work.name, include_mismatch=False)
        ):
            progress.info("%s: the nested test of the candidate effects", work.name)
            work.nested = nested_test(work, split, settings)
            if work.nested is not None:
                flagged.append(work)
                notes.append(f"{work.name}: {work.nested}")
    ranked = {w.name: score_candidates(w, split, settings) for w in flagged}
    source, chosen = choose(flagged, ranked, settings)

    progress.info("scoring: chain, free run and intervals of the answer")
    chains = chain_before_after(recording, twin, works, t, source, chosen)
    kpi_signal, kpi_shrink = chain_kpi_shrink(
        recording, *chains, source, chosen, split.score, notes
    )
    modules = module_reports(recording, works, flagged, source, chosen, chains, split)
    candidates = [
        c
        for name in sorted(ranked, key=lambda k: k != getattr(source, "name", None))
        for c in ranked[name]
    ]
    return Diagnosis(
        **verdict(source, chosen),
        kpi_shrink_pct=kpi_shrink,
        kpi_signal=kpi_signal,
        modules=modules,
        candidates=candidates,
        n_samples=n,
        n_train=n_train,
        n_choose=n_choose,
        dt=recording.dt,
        train_frac=train_frac,
        calibrated=tuple(w.name for w in works.values() if w.calibrated),
        notes=tuple(notes),
        settings=settings,
        also_needed=other_gaps(flagged, source, ranked, settings),
        twin_discretisation=discretisation,
        **free_run_rms(works, source, chosen, split),
        param_intervals=answer_intervals(source, chosen, split),
        series=scoring_series(recording, source, ranked, split.score),
    )
