"""One HMM fit in a fresh process: seconds per EM iteration and peak memory (benchmark).

Usage: python benchmarks/hmm_fit.py {dtwin,hmmlearn} T [n_restarts] [max_iter]
Prints one JSON line. Data: T×10 features from a 4-state switching Gaussian, seed 0.
Seconds per EM iteration = (time of the fit with max_iter − time with 1 iteration) / (extra
iterations), so start-up, random starts and the final posteriors are not counted.
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


def main() -> None:
    engine, n_steps = sys.argv[1], int(float(sys.argv[2]))
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
