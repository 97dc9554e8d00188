"""The monitor's sample lines written by the compiled loop are ``template % values``, byte for byte.

Numbers drawn over the whole range of doubles and the awkward ones: exact ties of the rounding
(``0.5``, ``40.5``, ``123456789012.5``), powers of two, ``-0.0``, the thresholds of ``%g``'s
and ``repr``'s exponent form, times on a sample grid, values beyond 1e±250 and non-finite ones
(left to Python, spliced back in place).
"""

from __future__ import annotations

import numpy as np
import pytest

from dtwin._jit import HAVE_NUMBA
from dtwin._validation import DtwinValueError
from dtwin.monitor._stream_kernels import write_lines
from dtwin.monitor.sample_lines import FEWEST_COMPILED, LineTemplate, powers_of_ten

TEMPLATE = '{"t": %r, "regime": "%s", "p": [%.12g, %.4g], "x": %.17g, "a": "%s", "y": %.1g}\n'
TEXTS = ("S1", "unknown", "Ünïcode", "")
AWKWARD = [0.0, -0.0, 0.5, 1.5, 2.5, 40.5, -40.5, 123456789012.5, 999999999999.5, 0.0001,
           0.00001, 9.99999999999e-5, 1e15, 1e16, 1e-250, 1e250, 1.7976931348623157e308,
           5e-324, 2.0**-1074, 2.0**60, 2.0**-30, 0.1 + 0.2, 1 / 3, 0.02 * 7, np.inf, -np.inf,
           np.nan]  # fmt: skip


def _draws(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    return [
        rng.normal(size=n),
        10.0 ** rng.uniform(-320, 308, n) * rng.choice([-1.0, 1.0], n),
        np.arange(n) * 0.02 + 7.0,
        np.round(rng.uniform(0, 1e5, n)) / 10.0 ** rng.integers(0, 6, n),
        rng.integers(-(10**15), 10**15, n).astype(float),
        2.0 ** rng.integers(-1000, 1000, n),
        np.resize(np.array(AWKWARD), n),
    ]  # fmt: skip


def test_rendered_lines_are_python_formatting():
    rng = np.random.default_rng(7)
    template = LineTemplate(TEMPLATE, TEXTS)
    assert template.n_floats == 5
    for draw in _draws(rng, 4000):
        with np.errstate(over="ignore"):
            floats = np.column_stack([draw, rng.permutation(draw), draw / 3, draw * 7, draw[::-1]])
        choices = rng.integers(0, len(TEXTS), (len(draw), 2))
        expected = "".join(
            TEMPLATE % (f[0], TEXTS[c[0]], f[1], f[2], f[3], TEXTS[c[1]], f[4])
            for f, c in zip(floats.tolist(), choices.tolist(), strict=True)
        )
        assert template.render(floats, choices) == expected


@pytest.mark.skipif(not HAVE_NUMBA, reason="without numba every line is Python's")
def test_the_compiled_loop_writes_almost_every_row_and_leaves_the_undecided_to_python():
    template = LineTemplate("%r %.12g\n", ())
    t = np.arange(10_000) * 0.02
    good = np.column_stack([t, np.sin(t)])
    hard = np.array([[0.3, 0.5], [0.3, 123456789012.5], [np.nan, 1.0], [0.3, 1e-300]])
    args = (template._kinds, template._precisions, template._literals, template._literal_ends,
            template._texts, template._text_ends, template._powers)  # fmt: skip
    _, _, written = write_lines(good, np.zeros((len(good), 0), dtype=np.int64), *args)
    assert written.sum() >= 9990  # a time that is a power of two (64.0) is left to Python
    text, ends, written = write_lines(hard, np.zeros((4, 0), dtype=np.int64), *args)
    assert written.tolist() == [True, False, False, False]
    assert text.tobytes().decode() == "0.3 0.5\n" and ends.tolist() == [8, 8, 8, 8]
    expected = "".join(f"{t!r} {x:.12g}\n" for t, x in hard.tolist())
    assert len(hard) >= FEWEST_COMPILED  # the compiled loop's rows and Python's, spliced
    assert template.render(hard, np.zeros((4, 0))) == expected


def test_powers_of_ten_hold_ten_to_the_k_beyond_a_double():
    powers = powers_of_ten(30)
    assert powers[30].tolist() == [1.0, 0.0]
    assert powers[30 + 22, 0] == 1e22 and powers[30 + 22, 1] == 0.0  # exact
    assert powers[30 + 23, 0] == 1e23 and powers[30 + 23, 1] != 0.0  # 10^23 is not a double
    assert powers[30 - 1, 0] + powers[30 - 1, 1] == 0.1


def test_a_template_with_another_field_is_refused():
    with pytest.raises(DtwinValueError, match="other than"):
        LineTemplate("%d\n", ())
    with pytest.raises(DtwinValueError, match="1 to 17 digits"):
        LineTemplate("%.18g\n", ())
