"""One HMM fit in a fresh process: seconds per EM iteration and peak memory (benchmark).

Usage: python benchmarks/hmm_fit.py {dtwin,hmmlearn} T [n_restarts] [max_iter]
       python benchmarks/hmm_fit.py {em-dtwin,em-hmmlearn} T [repeats] [K]
Prints one JSON line. Data: T×10 features from a 4-state switching Gaussian, seed 0.

``dtwin``/``hmmlearn``: one whole fit (random starts, EM, decoding, posteriors);
``seconds_per_iteration`` is the fit's seconds over its EM iterations (everything included),
``peak_mb`` the process's peak resident memory.

``em-*``: one EM iteration alone (K states, default 4, from one k-means++ start on the first
10,000 samples, BLAS on one thread), through
dtwin's compiled kernel (``dtwin._em_kernels.em``, on the ``(x, x²)`` rows that
:func:`dtwin.hmm.fit_hmm` gives it) or hmmlearn's own GaussianHMM; each engine's process imports
what its fit needs (``em-dtwin``: dtwin.hmm and the kernels, not hmmlearn or scikit-learn):

- ``seconds_per_iteration``: ``(t(fit, 1 + n iterations) − t(fit, 1 iteration)) / n``, so set-up,
  validation and the first call are not counted; median of ``repeats``;
- ``cpu_seconds_per_iteration``: the same in process CPU time (less sensitive to the other
  processes of a shared machine);
- ``iteration_peak_mb``: the peak of the memory numpy allocates during a 1-iteration fit
  (tracemalloc, MiB; ``X`` is allocated before);
- ``peak_mb``: the process's peak resident memory (MiB) after the measurements, with the
  interpreter and imports (``baseline_mb``) and ``X`` (``setup_mb``: after the data and the
  start, which comes from the first 10,000 samples);
- ``rss_file_mb``: of the resident memory at the end, the pages mapped from files (shared
  libraries: libllvmlite.so alone is 36–93 MiB of it, more when the file was written
  recently and sits whole in the page cache), as ``RssFile`` of ``/proc/self/status``
  (Linux; None elsewhere).
"""

from __future__ import annotations

import json
import resource
import sys
import time

import numpy as np


def features(n_steps: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    states = (np.arange(n_steps) * 4 // n_steps).astype(int)
    means = rng.normal(scale=1.5, size=(4, 10))
    return means[states] + rng.standard_normal((n_steps, 10))


def features_in_place(n_steps: int) -> np.ndarray:
    """:func:`features`, the same values, without its two T×10 temporaries."""
    rng = np.random.default_rng(0)
    means = rng.normal(scale=1.5, size=(4, 10))
    X = rng.standard_normal((n_steps, 10))
    states = (np.arange(n_steps) * 4 // n_steps).astype(int)
    for state in range(4):
        X[states == state] += means[state]
    return X


def _rss_file_mb() -> float | None:
    """Resident memory mapped from files (``RssFile``, MiB), or None where /proc is missing."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("RssFile:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def em_iteration(engine: str, n_steps: int, repeats: int, n_states: int = 4) -> dict:
    """Seconds per EM iteration and its memory peak (see the module docstring)."""
    import os
    import statistics
    import tracemalloc

    from dtwin import hmm
    from dtwin._multistart import one_blas_thread

    if engine == "em-dtwin":
        from dtwin import _em_kernels as kernels
    else:
        from hmmlearn.hmm import GaussianHMM

        from dtwin import _em_reference as reference

    baseline_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    X = features_in_place(n_steps)
    means, variances, _ = hmm._kmeanspp_start(X[:10_000], n_states, np.random.default_rng(0), 1e-3)
    setup_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024

    emission = np.stack([means, variances])
    rows = hmm._em_data(X).kernel if engine == "em-dtwin" else None

    def fit(n_iter: int) -> tuple[float, float]:
        if engine == "em-dtwin":  # the compiled kernel, every iteration in one call
            start, cpu = time.perf_counter(), time.process_time()
            with kernels.subnormals_flushed():  # as dtwin._multistart runs it
                kernels.em(kernels.GAUSSIAN, rows, emission, n_iter, -np.inf, 1e-3, False)
            return time.perf_counter() - start, time.process_time() - cpu
        model = GaussianHMM(n_states, "diag", n_iter=n_iter, tol=0.0, init_params="")
        uniform = np.full(n_states, 1.0 / n_states)
        reference.set_gaussian_params(
            model, uniform, np.tile(uniform, (n_states, 1)), means, variances
        )
        start, cpu = time.perf_counter(), time.process_time()
        model.fit(X)
        return time.perf_counter() - start, time.process_time() - cpu

    # n = 2 at T >= 1e5 (seconds per iteration); 20 below, where the later iterations cost more
    # (transition probabilities decay into subnormal numbers after ~10 iterations at K >= 12)
    span = 2 if n_steps >= 100_000 else 20
    with one_blas_thread():  # loads numba's BLAS (scipy's) first, as fit_hmm does
        fit(1)
        tracemalloc.start()
        fit(1)
        iteration_peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        samples, cpu_samples = [], []
        for _ in range(repeats):
            (more, more_cpu), (one, one_cpu) = fit(1 + span), fit(1)
            samples.append((more - one) / span)
            cpu_samples.append((more_cpu - one_cpu) / span)
    return {
        "engine": engine,
        "T": n_steps,
        "K": n_states,
        "iterations_timed": span,
        "repeats": repeats,
        "seconds_per_iteration": statistics.median(samples),
        "seconds_per_iteration_all": sorted(samples),
        "cpu_seconds_per_iteration": statistics.median(cpu_samples),
        "iteration_peak_mb": iteration_peak,
        "baseline_mb": baseline_mb,
        "setup_mb": setup_mb,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "rss_file_mb": _rss_file_mb(),
        "load_1min": os.getloadavg()[0],
    }


def main() -> None:
    engine, n_steps = sys.argv[1], int(float(sys.argv[2]))
    if engine.startswith("em-"):
        repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 3
        n_states = int(sys.argv[4]) if len(sys.argv) > 4 else 4
        print(json.dumps(em_iteration(engine, n_steps, repeats, n_states)))
        return
    n_restarts = int(sys.argv[3]) if len(sys.argv) > 3 else 10
    max_iter = int(sys.argv[4]) if len(sys.argv) > 4 else 500
    X = features(n_steps)
    start = time.perf_counter()
    if engine == "dtwin":
        from dtwin.hmm import fit_hmm

        fit = fit_hmm(X, 4, n_restarts=n_restarts, seed=0, max_iter=max_iter)
        iterations = int(fit.restarts["n_iter"].fillna(0).sum())
    else:
        from hmmlearn.hmm import GaussianHMM

        iterations = 0
        for restart in range(n_restarts):
            model = GaussianHMM(4, covariance_type="diag", n_iter=max_iter, random_state=restart)
            model.fit(X)
            iterations += model.monitor_.iter
    seconds = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        json.dumps(
            {
                "engine": engine,
                "T": n_steps,
                "restarts": n_restarts,
                "max_iter": max_iter,
                "seconds": seconds,
                "iterations": iterations,
                "seconds_per_iteration": seconds / max(iterations, 1),
                "peak_mb": peak_mb,
            }
        )
    )


if __name__ == "__main__":
    main()
