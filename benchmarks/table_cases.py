"""Recordings for the `table` benchmark section: a user's twin written as a table.

``oscillator``: a two-state expression module ``x' = w, w' = u − c·w − k·x`` (k = 4, c = 0.6,
dt = 0.05 s) whose real asset has a Coulomb friction of 0.5 (``tanh(w/0.01)``), driven by
random steps, integrated by scipy's solve_ivp (rtol 1e-8), 1 % white noise on ``x``. Written
as ``recording.csv`` and ``twin.yaml`` into a folder: ``python benchmarks/table_cases.py
N_SAMPLES FOLDER``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.integrate import solve_ivp

DT = 0.05
TWIN = {
    "dt": DT,
    "modules": {
        "osc": {
            "inputs": ["u"],
            "outputs": ["x"],
            "states": ["x", "w"],
            "params": {"k": 4.0, "c": 0.6},
            "derivatives": {"x": "w", "w": "u - c*w - k*x"},
        }
    },
    "noise": {"x": 0.01},
}


def write_oscillator(n_samples: int, folder: Path, seed: int = 0) -> None:
    """Write the oscillator case (module docstring) with ``n_samples`` samples into ``folder``."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-2, 2, n_samples // 50 + 1), 50)[:n_samples]

    def rhs(t, s):
        k = min(int(t / DT), n_samples - 1)
        x, w = s
        return [w, u[k] - 0.6 * w - 4 * x - 0.5 * np.tanh(w / 0.01)]

    times = np.arange(n_samples) * DT
    sol = solve_ivp(rhs, (0, times[-1]), [0, 0], t_eval=times, max_step=DT / 2, rtol=1e-8)
    x = sol.y[0] + 0.01 * rng.standard_normal(n_samples)
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame({"t": times, "u": u, "x": x}).to_csv(folder / "recording.csv", index=False)
    (folder / "twin.yaml").write_text(yaml.safe_dump(TWIN, sort_keys=False))


if __name__ == "__main__":
    write_oscillator(int(sys.argv[1]), Path(sys.argv[2]))
