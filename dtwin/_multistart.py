"""EM from several starts for the regime HMMs, one harness for every emission (paper §2.1, §5).

:func:`dtwin.hmm.fit_hmm` (Gaussian emissions) and :func:`dtwin.hmm_ar.fit_ar_hmm` (AR(1)
emissions) run their starts here: each start's EM through the chosen engine (``compiled``:
:func:`dtwin._em_kernels.em`; ``hmmlearn``: :mod:`dtwin._em_reference`), the same engine's
log-space recursions when the scaled ones fail, and one row per start with an honest status
(``ok``, ``max_iter``, ``not_monotone``, ``degenerate``, ``failed``). hmmlearn is imported only
by the reference engine, numba only when a start runs or a path is decoded.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np
import pandas as pd
from threadpoolctl import threadpool_limits

from dtwin._em_data import AR1, GAUSSIAN, EmData, EmError, EmRun
from dtwin._jit import HAVE_NUMBA

__all__ = [
    "AR1",
    "ENGINES",
    "GAUSSIAN",
    "MIN_OCCUPANCY",
    "RESTART_COLUMNS",
    "EmData",
    "EmError",
    "EmRun",
    "decode",
    "fit_starts",
    "kernel_array",
    "one_blas_thread",
    "restart_seeds",
    "run_start",
]

logger = logging.getLogger(__name__)

#: EM engines: numba kernels (default) or hmmlearn (the reference).
ENGINES = ("compiled", "hmmlearn")
_FALLBACK_WARNED: list[bool] = []  # the fallback is logged once per process


def available_engine(engine: str) -> str:
    """Return ``engine``, or ``"hmmlearn"`` for ``"compiled"`` when numba is not installed.

    The two engines give the same iterations and statuses
    (tests/concepts/test_hmm_engine.py), so the reference engine is the documented fallback of
    the compiled one.
    """
    if engine == "compiled" and not HAVE_NUMBA:
        if not _FALLBACK_WARNED:
            logger.warning("numba is not installed: EM runs in hmmlearn (hmm.engine: hmmlearn)")
            _FALLBACK_WARNED.append(True)
        return "hmmlearn"
    return engine


#: Whether this thread is inside :func:`one_blas_thread`.
_ONE_BLAS_THREAD = threading.local()


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Hold every BLAS library to one thread (threadpoolctl) for the block; nested blocks reuse it.

    ``threadpool_limits`` scans the process's loaded libraries on every entry (~4 ms); a BIC
    sweep entered it about twice per K, so the outermost block limits and the inner ones pass
    through. The compiled kernels call scipy's OpenBLAS, which numba loads with the first
    kernel; it is loaded here first, so that the limit holds it from the first start on.
    """
    if getattr(_ONE_BLAS_THREAD, "active", False):
        yield
        return
    if HAVE_NUMBA:
        import scipy.linalg.cython_blas  # noqa: F401  (numba's BLAS)
    with threadpool_limits(limits=1):
        _ONE_BLAS_THREAD.active = True
        try:
            yield
        finally:
            _ONE_BLAS_THREAD.active = False


#: A state whose expected occupancy ``Σ_t γ_t(k)`` falls below this many samples is "empty"
#: (half a sample, so that a state holding one outlier sample is not flagged by round-off).
MIN_OCCUPANCY = 0.5

#: Log-likelihood drops smaller than this times ``max(1, |LL|)`` count as round-off.
_LL_DROP_RTOL = 1e-9

#: Columns of a fit's table of starts (:attr:`dtwin.hmm.HmmFit.restarts`).
RESTART_COLUMNS = (
    "restart",
    "seed",
    "log_likelihood",
    "n_iter",
    "converged",
    "status",
    "implementation",
    "min_occupancy",
    "message",
)

#: Messages of the kernels' failure codes (:data:`dtwin._em_kernels.UNDERFLOW`, ...), as
#: hmmlearn's for the same failure; ``{}`` is the implementation.
_KERNEL_FAILURES = {
    "UNDERFLOW": "forward pass failed with underflow; consider using implementation='log'",
    "NON_FINITE": "non-finite log-likelihood or parameters ({})",
    "NOT_DISTRIBUTION": "startprob_ or transmat_ rows do not sum to 1 ({})",
}


def restart_seeds(seed: int | Sequence[int], n_restarts: int, first: int = 0) -> list[int]:
    """Seeds of starts ``first … n_restarts − 1``: children of ``SeedSequence(seed)``.

    Prefix-stable: the first starts of a longer run are those of a shorter one.
    """
    children = np.random.SeedSequence(seed).spawn(n_restarts)[first:]
    return [int(child.generate_state(1, dtype=np.uint32)[0]) for child in children]


def kernel_array(array: Any) -> np.ndarray:
    """Return ``array`` as the array type the cached kernels take: float64, C-contiguous, writable.

    Copied only when it is not one already (a read-only or strided array would make numba
    compile a new specialisation in the job); the kernels never write into their arguments, so
    the training rows are not copied per start (160 MB at T = 1e6, D = 10).
    """
    return np.require(array, dtype=float, requirements=["C_CONTIGUOUS", "WRITEABLE", "ALIGNED"])


def _compiled_em(
    data: EmData, emission: np.ndarray, implementation: str, options: dict[str, Any]
) -> EmRun:
    """EM in the compiled kernels, scaled (``scaling``) or log-space (``log``) recursions."""
    from dtwin import _em_kernels as kernels

    arrays = kernel_array(data.kernel), kernel_array(emission)
    with kernels.subnormals_flushed():
        code, history, stopped, startprob, transmat, fitted, final, posteriors = kernels.em(
            int(data.kind),
            *arrays,
            int(options["max_iter"]),
            float(options["tol"]),
            float(options["var_floor"]),
            implementation == "log",
        )
    if code != kernels.OK:
        failure = next(name for name in _KERNEL_FAILURES if getattr(kernels, name) == code)
        raise EmError(_KERNEL_FAILURES[failure].format(implementation))
    history = np.append(history, final)
    return EmRun(startprob, transmat, fitted, history, bool(stopped), posteriors, implementation)


def run_start(
    data: EmData, emission: np.ndarray, engine: str, options: dict[str, Any]
) -> tuple[EmRun | None, list[str]]:
    """Run EM from one emission start (π, A uniform); scaled recursions, then log-space ones.

    Both in the engine's implementation (compiled, or hmmlearn's ``scaling`` and ``log``).
    Returns the run (None if both failed) and the failure messages, ``"<implementation>: …"``.
    """
    messages = []
    engine = available_engine(engine)
    for implementation in ("scaling", "log"):
        try:
            if engine == "compiled":
                return _compiled_em(data, emission, implementation, options), messages
            from dtwin import _em_reference

            return _em_reference.run_em(data, emission, implementation, options), messages
        except (EmError, ValueError, FloatingPointError, RuntimeError) as error:
            messages.append(f"{implementation}: {error}")
    return None, messages


def _monotone(history: np.ndarray) -> bool:
    steps = np.diff(history)
    if steps.size == 0:
        return True
    allowed = _LL_DROP_RTOL * max(1.0, float(np.max(np.abs(history))))
    return bool(steps.min() >= -allowed)


def _start_row(seed: int, run: EmRun | None, messages: list[str]) -> dict[str, Any]:
    """Return the table row of one start that ran EM (statuses: see :func:`fit_starts`)."""
    row: dict[str, Any] = {
        "seed": seed,
        "log_likelihood": math.nan,
        "n_iter": 0,
        "converged": False,
        "status": "failed",
        "implementation": "",
        "min_occupancy": math.nan,
        "message": "; ".join(messages),
    }
    if run is None:
        return row
    occupancy = run.occupancy
    row.update(
        log_likelihood=float(run.history[-1]),
        n_iter=len(run.history) - 1,
        implementation=run.implementation,
        min_occupancy=float(occupancy.min()),
    )
    if occupancy.min() < MIN_OCCUPANCY:
        row["status"] = "degenerate"
        row["message"] = (row["message"] + "; " if messages else "") + "a state emptied"
    elif not _monotone(run.history):
        row["status"] = "not_monotone"
    elif not run.stopped:
        row["status"] = "max_iter"
    else:
        row.update(status="ok", converged=True)
    return row


def fit_one_start(
    data: EmData,
    seed: int,
    initial: tuple[np.ndarray, np.ndarray],
    engine: str,
    options: dict[str, Any],
) -> tuple[dict[str, Any], EmRun | None]:
    """EM from one start ``initial = (emission (P, K, D), occupancy (K,))``; row and usable run.

    A start whose initial occupancy leaves a state below :data:`MIN_OCCUPANCY` samples, or
    whose emission is not finite, is ``degenerate`` and not run.
    """
    emission, occupancy = initial
    if not np.all(occupancy >= MIN_OCCUPANCY) or not np.isfinite(emission).all():
        row = _start_row(seed, None, [])
        row.update(status="degenerate", min_occupancy=float(np.min(occupancy)))
        row["message"] = f"random start left a state with < {MIN_OCCUPANCY} samples of weight"
        return row, None
    run, messages = run_start(data, emission, engine, options)
    row = _start_row(seed, run, messages)
    return row, (run if row["status"] not in ("failed", "degenerate") else None)


def fit_starts(
    data: EmData,
    seeds: Sequence[int],
    initial: Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray]],
    engine: str,
    options: dict[str, Any],
    first_restart: int = 1,
    label: str = "fit_hmm",
) -> tuple[pd.DataFrame, dict[int, EmRun]]:
    """Run one EM start per seed; return the table of starts and the usable runs by number.

    ``initial(rng)`` draws a start's emission and initial occupancy from its generator.
    Statuses: ``ok`` (the tolerance stopped it, log-likelihood never fell beyond round-off),
    ``max_iter`` (usable, not converged), ``not_monotone``, ``degenerate`` (a state with
    expected occupancy below :data:`MIN_OCCUPANCY`), ``failed`` (both implementations failed).
    """
    rows, runs = [], {}
    best: tuple[float, int] | None = None  # log-likelihood and number of the best start so far
    for restart, seed in enumerate(seeds, start=first_restart):
        row, run = fit_one_start(data, seed, initial(np.random.default_rng(seed)), engine, options)
        rows.append({"restart": restart, **row})
        logger.info(
            "%s restart %d: status=%s logL=%.4f n_iter=%d",
            label,
            restart,
            row["status"],
            row["log_likelihood"],
            row["n_iter"],
        )
        if run is not None:
            runs[restart] = run
            best = _keep_best_posteriors(runs, best, restart, row["log_likelihood"])
    return pd.DataFrame(rows, columns=list(RESTART_COLUMNS)), runs


def _keep_best_posteriors(
    runs: dict[int, EmRun], best: tuple[float, int] | None, restart: int, log_likelihood: float
) -> tuple[float, int]:
    """Drop the posteriors of every run but the best so far (highest log-likelihood, first of ties).

    The best start of a fit is the only one whose posteriors are read (``_best_restart`` of
    :mod:`dtwin.hmm`); returns the new ``(log-likelihood, restart)`` of the best.
    """
    if best is not None and not log_likelihood > best[0]:
        runs[restart] = replace(runs[restart], posteriors=None)
        return best
    if best is not None:
        runs[best[1]] = replace(runs[best[1]], posteriors=None)
    return log_likelihood, restart


def decode(data: EmData, run: EmRun, engine: str) -> np.ndarray:
    """Viterbi path (Eq. (10)) of the training rows under ``run``'s parameters, states 0 … K−1."""
    if available_engine(engine) == "hmmlearn":
        from dtwin import _em_reference

        return _em_reference.viterbi(data, run)
    from dtwin import _em_kernels as kernels

    arrays = (data.kernel, run.emission, run.startprob, run.transmat)
    return kernels.viterbi(int(data.kind), *(kernel_array(a) for a in arrays))
