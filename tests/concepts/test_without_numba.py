"""dtwin works where numba is missing: the force loop runs in Python, EM falls back to hmmlearn."""

import json
import subprocess
import sys
import textwrap

import numpy as np

from dtwin.hmm import fit_hmm

SCRIPT = textwrap.dedent(
    """
    import sys
    sys.modules["numba"] = None  # `import numba` now fails, as in an environment without it
    import json
    import numpy as np
    from dtwin._jit import HAVE_NUMBA
    from dtwin._force_kernels import ForceLaw, force_windows
    from dtwin.hmm import fit_hmm

    rng = np.random.default_rng(3)
    drive = rng.normal(0, 1e-3, (2, 50, 2))
    steps = (0.99, 0.01, -0.01, 0.98, 1e-4, 1e-2, 1e-4, 1e-2)
    law = ForceLaw("tanh_friction", (0.1, 0.01))
    out = force_windows(drive, np.zeros(2), np.zeros(2), steps, law, 1.0)
    X = np.concatenate([rng.normal(-2, 1, (80, 2)), rng.normal(2, 1, (80, 2))])
    fit = fit_hmm(X, 2, n_restarts=2, seed=1)
    loaded = sys.modules.get("numba") is not None
    finite = bool(np.isfinite(out).all())
    print(json.dumps({"numba": HAVE_NUMBA, "numba_loaded": loaded, "finite": finite,
                      "loglik": fit.log_likelihood}))
    """
)


def test_diagnoser_kernels_and_em_run_without_numba():
    """A process that cannot import numba still steps a force law and fits an HMM (hmmlearn)."""
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
