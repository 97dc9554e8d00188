"""dtwin works where numba is missing: the force loop runs in Python, EM falls back to hmmlearn."""

import json
import subprocess
import sys
import textwrap

import numpy as np

from dtwin.hmm import fit_hmm

#: A continuous asset's run with a friction law (dtwin.twin._force_kernels.rk4_chain's arguments).
#: And a rig's (rk4_plant): a drive given at every Runge-Kutta instant, then a PD loop.
RK4_SETUP = """
from dtwin.twin._force_kernels import ForceLaw, PdLoop
u = np.sin(np.arange(60) * 0.3)
RK4_ARGS = (u, 0.05, 1.3, 0.4, 40.0, 0.01, 0.1 * u[::-1], np.cos(np.arange(60)), 20,
            ForceLaw("generalised_stribeck", (0.3, 0.2, 0.05, 1.4, 0.02, 0.1)))
STAGES = np.sin(np.arange(60 * 10 * 3) * 0.01).reshape(60, 10, 3)
LAW = ForceLaw("stribeck_friction", (0.3, 0.2, 0.05, 0.02))
PLANT_ARGS = [(STAGES, 1.3, 0.4, 40.0, 0.01, 10, LAW),
              (u, 1.3, 0.4, 40.0, 0.01, 10, LAW, PdLoop(900.0, 40.0, u, u[::-1]), 1e-3 * u)]
"""

SCRIPT = (
    textwrap.dedent(
        """
    import sys
    sys.modules["numba"] = None  # `import numba` now fails, as in an environment without it
    import json
    import numpy as np
    from dtwin._jit import HAVE_NUMBA
    from dtwin.twin._force_kernels import ForceLaw, force_windows, rk4_chain, rk4_plant
    from dtwin.hmm import fit_hmm
    """
    )
    + RK4_SETUP
    + textwrap.dedent(
        """
    rng = np.random.default_rng(3)
    drive = rng.normal(0, 1e-3, (2, 50, 2))
    steps = (0.99, 0.01, -0.01, 0.98, 1e-4, 1e-2, 1e-4, 1e-2)
    law = ForceLaw("tanh_friction", (0.1, 0.01))
    out = force_windows(drive, np.zeros(2), np.zeros(2), steps, law, 1.0)
    X = np.concatenate([rng.normal(-2, 1, (80, 2)), rng.normal(2, 1, (80, 2))])
    fit = fit_hmm(X, 2, n_restarts=2, seed=1)
    chain = rk4_chain(*RK4_ARGS)
    plant = [np.concatenate([s.ravel(), f]).tobytes().hex()
             for s, f in (rk4_plant(*args) for args in PLANT_ARGS)]
    loaded = sys.modules.get("numba") is not None
    finite = bool(np.isfinite(out).all())
    print(json.dumps({"numba": HAVE_NUMBA, "numba_loaded": loaded, "finite": finite,
                      "loglik": fit.log_likelihood, "rk4": chain.tobytes().hex(), "plant": plant}))
    """
    )
)


def test_diagnoser_kernels_and_em_run_without_numba():
    """A process that cannot import numba still steps a force law and fits an HMM (hmmlearn).

    The continuous asset's and the rigs' Runge-Kutta loops, run by the interpreter there, give
    the bits of the compiled loops here.
    """
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, check=False, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["numba"] is False and result["numba_loaded"] is False
    assert result["finite"]
    rng = np.random.default_rng(3)
    rng.normal(0, 1e-3, (2, 50, 2))
    X = np.concatenate([rng.normal(-2, 1, (80, 2)), rng.normal(2, 1, (80, 2))])
    reference = fit_hmm(X, 2, n_restarts=2, seed=1, engine="hmmlearn").log_likelihood
    assert np.isclose(result["loglik"], reference, rtol=1e-9)
    setup = {"np": np}
    exec(RK4_SETUP, setup)  # the same run where numba is installed: the same bits
    from dtwin.twin._force_kernels import rk4_chain, rk4_plant

    assert result["rk4"] == rk4_chain(*setup["RK4_ARGS"]).tobytes().hex()
    for args, bits in zip(setup["PLANT_ARGS"], result["plant"], strict=True):
        states, held = rk4_plant(*args)
        assert bits == np.concatenate([states.ravel(), held]).tobytes().hex()
