"""Compiled EM for the regime HMMs: one call runs every iteration of one EM start (paper §2.1).

The E-step is hmmlearn 0.3.3's ``scaling`` implementation written out in numba, with the same
recursions, the same summation order and the same underflow test (``forward_scaling``,
``backward_scaling``, ``compute_scaling_xi_sum``, ``viterbi`` of its ``_hmmc`` module); the
loops are ordered so that the inner one runs over contiguous memory and vectorises without
reassociating any sum. The densities are exponentiated by a vectorised ``exp`` (:func:`_exp`,
within 1 ulp of libm's; numpy's, which hmmlearn calls, is within 1 ulp of it too), so the
numbers differ from hmmlearn's by round-off only. The M-step is hmmlearn's maximum-likelihood
update with the priors switched off (π and A: normalised expected counts; Gaussian emissions:
weighted means and variances; AR(1) emissions: weighted least squares), then the variance
floor; the stopping rule is depmixS4's ``(LL − LL_old)/|LL_old| < tol``. Arrays are time-first
``(T, D)``.

Subnormal numbers: once EM has settled, transition probabilities of unused transitions and
the scaled forward variables of far-away states decay through the subnormal range (below
2.2250738585072014e-308) towards 0, and every product with a subnormal operand or result takes
the processor's slow path (about 30 % of an iteration's time at K ≥ 12 late in EM, measured at
T = 1000, D = 10). :func:`em` therefore runs inside :func:`subnormals_flushed` on x86-64
(called by :mod:`dtwin._multistart`): the SSE control register's flush-to-zero and
denormals-are-zero bits make any result or operand below the smallest normal float exactly 0.
A probability that small contributes below 1e-300 to any sum here, so log-likelihoods,
parameters and posteriors move by round-off at most; every iteration count, status and decoded
path of the paper pipeline is unchanged (every table byte-identical). A transition
probability flushed to 0 stays 0, as one that underflows. Elsewhere (another architecture, or
the hmmlearn engine) subnormals are kept.

Where the scaled forward pass underflows (a sample far from every state: all its emission
densities below 1e-300), :func:`em` reruns the start in log space (``log_space``), hmmlearn's
``implementation="log"`` compiled the same way (:func:`_estep_log`), and :func:`score`
continues in log space.

Functions are compiled on first use and cached on disk (``cache=True``, numba's per-function
cache files, written atomically), so a process that finds the cache loads machine code instead
of compiling; ``make venv`` warms it with :func:`warm_up`.
"""

from __future__ import annotations

import math
import platform
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = [
    "AR1",
    "GAUSSIAN",
    "NON_FINITE",
    "NOT_DISTRIBUTION",
    "OK",
    "UNDERFLOW",
    "em",
    "score",
    "subnormals_flushed",
    "viterbi",
]

#: Return codes of :func:`em`.
OK, UNDERFLOW, NON_FINITE, NOT_DISTRIBUTION = 0, 1, 2, 3

#: ``kind`` of the kernels: diagonal Gaussian or diagonal Gaussian AR(1) emissions.
GAUSSIAN, AR1 = 0, 1

#: hmmlearn's underflow bound on a forward normaliser (``min_sum`` of ``forward_scaling``).
_MIN_SUM = 1e-300

#: The SSE control register (MXCSR) bits flush-to-zero (0x8000: a result below the smallest
#: normal float becomes 0) and denormals-are-zero (0x0040: such an operand reads as 0).
_FLUSH_BITS = 0x8040

#: Whether the processor has the SSE control register (x86-64); elsewhere nothing is flushed.
_HAS_MXCSR = platform.machine().lower() in ("x86_64", "amd64")


@intrinsic
def _mxcsr(typingctx, value):
    """Swap the thread's SSE control register with ``value`` (uint32); returns the old value."""

    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        hook = ir.FunctionType(ir.VoidType(), [pointer])
        store = cgutils.get_or_insert_function(builder.module, hook, "llvm.x86.sse.stmxcsr")
        load = cgutils.get_or_insert_function(builder.module, hook, "llvm.x86.sse.ldmxcsr")
        slot = cgutils.alloca_once(builder, ir.IntType(32))
        builder.call(store, [builder.bitcast(slot, pointer)])
        old = builder.load(slot)
        builder.store(args[0], slot)
        builder.call(load, [builder.bitcast(slot, pointer)])
        return old

    return types.uint32(types.uint32), codegen


@njit(cache=True)
def _swap_control(value):
    """Set the SSE control register to ``value``; returns its previous value (x86-64 only)."""
    return _mxcsr(np.uint32(value))


@contextmanager
def subnormals_flushed() -> Iterator[None]:
    """Within the block, this thread's floating-point arithmetic flushes subnormals to 0.

    On x86-64 the SSE control register gets its flush-to-zero and denormals-are-zero bits
    (:data:`_FLUSH_BITS`) and is restored on exit; every result or operand of magnitude below
    2.2250738585072014e-308 is then exactly 0 (in compiled kernels, numpy and Python floats
    alike). Elsewhere it does nothing. The register is per thread and the block is entered
    and left by separate compiled calls, so no kernel's arithmetic moves across the switch.
    """
    if not _HAS_MXCSR:
        yield
        return
    previous = int(_swap_control(0x1F80))  # read it (0x1F80: the default, nothing flushed)
    _swap_control(previous | _FLUSH_BITS)
    try:
        yield
    finally:
        _swap_control(previous)


@njit(cache=True)
def _row_sum(a, row, start, stop):
    """``a[row, start:stop].sum()`` in numpy's pairwise order, without a view.

    Bit for bit up to 128 terms (numpy's block; more states or features than that are not
    modelled); longer rows are summed in order. Views cost a reference count each, so the
    loops here index the 2-D arrays directly.
    """
    n = stop - start
    if n < 8 or n > 128:
        total = 0.0
        for i in range(start, stop):
            total += a[row, i]
        return total
    r0, r1, r2, r3 = a[row, start], a[row, start + 1], a[row, start + 2], a[row, start + 3]
    r4, r5, r6, r7 = a[row, start + 4], a[row, start + 5], a[row, start + 6], a[row, start + 7]
    i = start + 8
    while i < stop - n % 8:
        r0 += a[row, i]
        r1 += a[row, i + 1]
        r2 += a[row, i + 2]
        r3 += a[row, i + 3]
        r4 += a[row, i + 4]
        r5 += a[row, i + 5]
        r6 += a[row, i + 6]
        r7 += a[row, i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < stop:
        total += a[row, i]
        i += 1
    return total


@njit(cache=True)
def _numpy_sum(a):
    """``a.sum()`` of a vector in numpy's pairwise order, bit for bit."""
    return _row_sum(a.reshape(1, -1), 0, 0, a.shape[0])


@njit(cache=True)
def _predict(fwd, t, transmat, frameprob, out):
    """``out_j = (Σ_i α_t−1(i) A_ij) b_j(e_t)``, the sum over i in order (hmmlearn's).

    Two terms of the sum per pass over j (``(out + a) + b`` is the sequential order), so
    the running sums go through memory half as often; the j loop vectorises.
    """
    n_states = out.shape[0]
    for j in range(n_states):
        out[j] = 0.0
    i = 0
    while i + 2 <= n_states:
        w0, w1 = fwd[t - 1, i], fwd[t - 1, i + 1]
        for j in range(n_states):
            out[j] = (out[j] + w0 * transmat[i, j]) + w1 * transmat[i + 1, j]
        i += 2
    if i < n_states:
        w0 = fwd[t - 1, i]
        for j in range(n_states):
            out[j] += w0 * transmat[i, j]
    for j in range(n_states):
        out[j] *= frameprob[t, j]


#: exp(x) = 2^n · e^r with n = round(x/ln 2), r = x − n ln 2 (|r| ≤ ½ ln 2; ln 2 split in two
#: parts, the first exact in n·ln2_hi): Cody and Waite's reduction, as fdlibm's ``exp``.
_LOG2E, _LN2_HI, _LN2_LO = (
    1.4426950408889634,
    6.93147180369123816490e-01,
    1.90821492927058770002e-10,
)
#: Taylor coefficients 1/i! of e^r, i = 13 … 2 (the truncation error r^14/14! < 5e-18 relative).
_EXP_TAYLOR = tuple(1.0 / math.factorial(i) for i in range(13, 1, -1))


@njit(cache=True, inline="always")
def _exp(x):
    """e^x within 1 ulp of ``math.exp`` (correctly rounded on 90 % of inputs), vectorisable.

    Horner's scheme of the Taylor polynomial on the reduced argument, then the scaling by
    2^n as two exact powers of two built from their bits (so subnormal results round once);
    x is clamped to [−746, 710] (0 and ∞ beyond), NaN stays NaN.
    """
    x = -746.0 if x < -746.0 else (710.0 if x > 710.0 else x)
    n = math.floor(x * _LOG2E + 0.5)
    r = (x - n * _LN2_HI) - n * _LN2_LO
    p = _EXP_TAYLOR[0]
    for c in _EXP_TAYLOR[1:]:
        p = p * r + c
    p = (p * r + 1.0) * r + 1.0
    k = np.int64(n)
    half = k >> 1
    first = np.int64((half + 1023) << 52).view(np.float64)
    second = np.int64((k - half + 1023) << 52).view(np.float64)
    return (p * first) * second


@njit(cache=True)
def _exp_all(a):
    """Replace every element of a C-contiguous array by its exponential (one vectorised loop)."""
    flat = a.reshape(-1)
    for i in range(flat.shape[0]):
        flat[i] = _exp(flat[i])


@njit(cache=True)
def _forward(startprob, transmat, frameprob, fwd, scaling):
    """Scaled forward pass (Eq. (4)); returns log p(X), or NaN on hmmlearn's underflow.

    hmmlearn's ``forward_scaling``: every α_t is scaled to sum 1 (the scale is ``1/Σ_j``,
    summed in order; below 1e-300 the pass fails), ``log p(X) = −Σ_t log scale_t``.
    """
    n_steps, n_states = frameprob.shape
    row = np.empty(n_states)
    for j in range(n_states):
        row[j] = startprob[j] * frameprob[0, j]
    for t in range(n_steps):
        if t > 0:
            _predict(fwd, t, transmat, frameprob, row)
        total = 0.0
        for j in range(n_states):
            total += row[j]
        if total < _MIN_SUM:
            return math.nan
        scale = 1.0 / total
        scaling[t] = scale
        for j in range(n_states):
            fwd[t, j] = row[j] * scale
    log_prob = 0.0
    for t in range(n_steps):
        log_prob -= math.log(scaling[t])
    return log_prob


@njit(cache=True)
def _backward_step(transmat_t, ahead, row):
    """``row_i = Σ_j Aᵀ_ji ahead_j``, the sum over j in order, two terms per pass over i."""
    n_states = row.shape[0]
    for i in range(n_states):
        row[i] = 0.0
    j = 0
    while j + 2 <= n_states:
        b0, b1 = ahead[j], ahead[j + 1]
        for i in range(n_states):
            row[i] = (row[i] + transmat_t[j, i] * b0) + transmat_t[j + 1, i] * b1
        j += 2
    if j < n_states:
        b0 = ahead[j]
        for i in range(n_states):
            row[i] += transmat_t[j, i] * b0


@njit(cache=True)
def _backward(transmat_t, frameprob, scaling, bwd):
    """Scaled backward pass; ``transmat_t`` is Aᵀ (contiguous), sums run over j in order.

    Row t ≥ 1 of ``frameprob`` is overwritten by ``b_t ⊙ β_t``, the ξ-sum's right factor
    (b_t is not read again), so the E-step needs no fourth (T, K) array for it.
    """
    n_steps, n_states = frameprob.shape
    ahead, row = np.empty(n_states), np.empty(n_states)
    for i in range(n_states):
        bwd[n_steps - 1, i] = scaling[n_steps - 1]
    for t in range(n_steps - 2, -1, -1):
        for j in range(n_states):
            ahead[j] = frameprob[t + 1, j] * bwd[t + 1, j]
            frameprob[t + 1, j] = ahead[j]
        _backward_step(transmat_t, ahead, row)
        for i in range(n_states):
            bwd[t, i] = row[i] * scaling[t]


@njit(cache=True)
def _posteriors(fwd, bwd, out):
    """γ_t ∝ α_t·β_t, rows normalised as hmmlearn's ``normalize(axis=1)`` (zero rows kept).

    ``out`` may be ``bwd`` (γ then replaces β in place).
    """
    n_steps, n_states = fwd.shape
    for t in range(n_steps):
        for k in range(n_states):
            out[t, k] = fwd[t, k] * bwd[t, k]
        total = _row_sum(out, t, 0, n_states)
        if total == 0.0:
            total = 1.0
        for k in range(n_states):
            out[t, k] /= total


@njit(cache=True)
def _xi_sum(fwd, transmat, weighted, products, out):
    """Σ_t ξ_t(i, j) of the scaled lattices (hmmlearn's ``compute_scaling_xi_sum``).

    ``Σ_t α_t(i) A_ij b_j(e_t+1) β_t+1(j) = A_ij · [α_0:T−1ᵀ (b ⊙ β)_1:T]_ij``: A is constant
    over t, so the sum is one matrix product (BLAS, into ``products``) instead of T·K² scalar
    updates; rows 1 … T−1 of ``weighted`` hold ``b ⊙ β`` (:func:`_backward`).
    """
    np.dot(fwd[:-1].T, weighted[1:], products)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = transmat[i, j] * products[i, j]


@njit(cache=True)
def _normalise(counts, previous, zero_rows_kept):
    """Hmmlearn's π/A update with priors 1: ``max(counts, 0)``, zeros kept, rows normalised.

    ``normalize(a)`` of a vector divides by the sum; ``normalize(a, axis=1)`` divides rows with
    a zero sum by 1 (``zero_rows_kept``).
    """
    out = np.empty_like(counts)
    for i in range(counts.shape[0]):
        for j in range(counts.shape[1]):
            out[i, j] = 0.0 if previous[i, j] == 0.0 else max(0.0 + counts[i, j], 0.0)
        total = _row_sum(out, i, 0, counts.shape[1])
        if zero_rows_kept and total == 0.0:
            total = 1.0
        for j in range(counts.shape[1]):
            out[i, j] /= total
    return out


#: Positions in :func:`_lattices`' tuple: the densities (then the ξ-sum's right factor), the
#: forward lattice, β (then the posteriors γ), the (K, K) product and the (T,) forward scales.
_FRAMEPROB, _FWD, _GAMMA, _PRODUCTS, _SCALING = 0, 1, 2, 3, 4


@njit(cache=True)
def _lattices(n_steps, n_states):
    """Return the E-step's buffers, reused by every iteration of a start (see :func:`_estep`).

    Three (T, K) arrays (24·T·K bytes: 96 MB at T = 1e6, K = 4), a (K, K) one and the (T,)
    scales, in the order of :data:`_FRAMEPROB` … :data:`_SCALING`.
    """
    frameprob, fwd = np.empty((n_steps, n_states)), np.empty((n_steps, n_states))
    gamma, products = np.empty((n_steps, n_states)), np.empty((n_states, n_states))
    return frameprob, fwd, gamma, products, np.empty(n_steps)


@njit(cache=True)
def _estep(kind, data, emission, startprob, transmat, buffers, xi):
    """Emission densities, forward, backward, γ and the ξ-sum; returns log p(X) (NaN on underflow).

    ``buffers`` are :func:`_lattices`'; the densities become the ξ-sum's right factor ``b ⊙ β``
    and β becomes γ in place, so γ ends in ``buffers[_GAMMA]``, Σ_t ξ_t in ``xi``.
    """
    frameprob, fwd, gamma, products, scaling = buffers
    _log_frameprob(kind, data, emission, frameprob)
    _exp_all(frameprob)
    log_prob = _forward(startprob, transmat, frameprob, fwd, scaling)
    if math.isnan(log_prob):
        return log_prob
    _backward(np.ascontiguousarray(transmat.T), frameprob, scaling, gamma)
    _xi_sum(fwd, transmat, frameprob, products, xi)
    _posteriors(fwd, gamma, gamma)
    return log_prob


@njit(cache=True)
def _logsumexp(values):
    """``log Σ_i exp(v_i)`` of a vector, shifted by its maximum (−∞ if every entry is −∞)."""
    peak = -np.inf
    for i in range(values.shape[0]):
        peak = max(peak, values[i])
    if not np.isfinite(peak):
        return peak
    total = 0.0
    for i in range(values.shape[0]):
        total += _exp(values[i] - peak)
    return math.log(total) + peak


@njit(cache=True)
def _log_forward(log_start, log_trans_t, log_frameprob, fwd):
    """Log-space forward pass (Eq. (4)): ``log α_t(j)``; returns log p(X).

    hmmlearn's ``forward_log``: ``log α_t(j) = logsumexp_i(log α_t−1(i) + log A_ij) + log b_j``;
    ``log_trans_t`` is log Aᵀ (contiguous rows over i).
    """
    n_steps, n_states = log_frameprob.shape
    terms = np.empty(n_states)
    for j in range(n_states):
        fwd[0, j] = log_start[j] + log_frameprob[0, j]
    for t in range(1, n_steps):
        for j in range(n_states):
            for i in range(n_states):
                terms[i] = fwd[t - 1, i] + log_trans_t[j, i]
            fwd[t, j] = _logsumexp(terms) + log_frameprob[t, j]
    return _logsumexp(fwd[n_steps - 1])


@njit(cache=True)
def _log_backward(log_trans, log_frameprob, bwd):
    """Log-space backward pass (hmmlearn's ``backward_log``), ``log β_T = 0``.

    Row t ≥ 1 of ``log_frameprob`` is overwritten by ``log b_t + log β_t``, the ξ-sum's right
    factor (as :func:`_backward`).
    """
    n_steps, n_states = log_frameprob.shape
    terms = np.empty(n_states)
    for i in range(n_states):
        bwd[n_steps - 1, i] = 0.0
    for t in range(n_steps - 2, -1, -1):
        for j in range(n_states):
            log_frameprob[t + 1, j] = log_frameprob[t + 1, j] + bwd[t + 1, j]
        for i in range(n_states):
            for j in range(n_states):
                terms[j] = log_trans[i, j] + log_frameprob[t + 1, j]
            bwd[t, i] = _logsumexp(terms)


@njit(cache=True)
def _xi_peaks(fwd, weighted, peaks):
    """``peaks_ij = max_t (log α_t(i) + log b_j + log β_t+1(j))`` (−∞ if every term is)."""
    n_steps, n_states = fwd.shape
    peaks[:, :] = -np.inf
    for t in range(n_steps - 1):
        for i in range(n_states):
            for j in range(n_states):
                peaks[i, j] = max(peaks[i, j], fwd[t, i] + weighted[t + 1, j])


@njit(cache=True)
def _log_xi_sum(fwd, log_trans, weighted, log_prob, peaks, out):
    """Σ_t ξ_t(i, j) from log-space lattices (hmmlearn's ``compute_log_xi_sum``, exponentiated).

    ``log Σ_t ξ_t(i, j) = log A_ij + logsumexp_t(log α_t(i) + log b_j + log β_t+1(j)) − log p``,
    each (i, j) shifted by its own maximum over t (two passes; ``peaks`` (K, K) holds them).
    """
    n_steps, n_states = fwd.shape
    _xi_peaks(fwd, weighted, peaks)
    out[:, :] = 0.0
    for t in range(n_steps - 1):
        for i in range(n_states):
            for j in range(n_states):
                if np.isfinite(peaks[i, j]):
                    out[i, j] += _exp(fwd[t, i] + weighted[t + 1, j] - peaks[i, j])
    for i in range(n_states):
        for j in range(n_states):
            if np.isfinite(peaks[i, j]) and out[i, j] > 0.0:
                out[i, j] = _exp(log_trans[i, j] + peaks[i, j] + math.log(out[i, j]) - log_prob)
            else:
                out[i, j] = 0.0


@njit(cache=True)
def _log_posteriors(fwd, bwd, out):
    """γ_t = exp(log α_t + log β_t − logsumexp_k(…)) (hmmlearn's ``_compute_posteriors_log``).

    ``out`` may be ``bwd`` (γ then replaces log β in place).
    """
    n_steps, n_states = fwd.shape
    for t in range(n_steps):
        for k in range(n_states):
            out[t, k] = fwd[t, k] + bwd[t, k]
        norm = _logsumexp(out[t])
        for k in range(n_states):
            out[t, k] = _exp(out[t, k] - norm)


@njit(cache=True)
def _estep_log(kind, data, emission, startprob, transmat, buffers, xi):
    """:func:`_estep` in log space (hmmlearn's ``implementation="log"``), for when it underflows.

    The same statistics, exact where every emission density of a sample underflows (an
    outlier far from every state): returns log p(X) (−∞ or NaN if not finite).
    """
    log_frameprob, fwd, gamma, products, _ = buffers
    _log_frameprob(kind, data, emission, log_frameprob)
    log_start, log_trans = np.log(startprob), np.log(transmat)
    log_prob = _log_forward(log_start, np.ascontiguousarray(log_trans.T), log_frameprob, fwd)
    if not np.isfinite(log_prob):
        return log_prob
    _log_backward(log_trans, log_frameprob, gamma)
    _log_xi_sum(fwd, log_trans, log_frameprob, log_prob, products, xi)
    _log_posteriors(fwd, gamma, gamma)
    return log_prob


@njit(cache=True)
def _weighted_sums(gamma, columns):
    """Σ_t γ_t(k) (summed in order) and γᵀ·columns (BLAS), shapes (K,) and (K, C)."""
    n_steps, n_states = gamma.shape
    occupancy = np.zeros(n_states)
    for t in range(n_steps):
        for k in range(n_states):
            occupancy[k] += gamma[t, k]
    return occupancy, np.dot(gamma.T, columns)


@njit(cache=True)
def _transition_mstep(startprob, transmat, gamma, xi):
    """π and A from the E-step statistics (Eqs. (7)–(8))."""
    start = _normalise(gamma[:1].copy(), startprob.reshape(1, -1), False)[0]
    return start, _normalise(xi, transmat, True)


@njit(cache=True)
def _row_constant(quadratic, variances):
    """``Σ_d quadratic_d + Σ_d log(2π σ_d²)`` in numpy's summation order."""
    logs = np.empty(variances.shape[0])
    for d in range(variances.shape[0]):
        logs[d] = math.log(2.0 * math.pi * variances[d])
    return _numpy_sum(quadratic) + _numpy_sum(logs)


@njit(cache=True)
def _gaussian_weights(emission):
    """Weights (2D, K) of the rows ``(x, x²)`` and the constant (K,) of ``−2 log N``.

    ``Σ_d (x − μ)²/σ² + log 2πσ² = x·(−2μ/σ²) + x²·(1/σ²) + Σ_d μ²/σ² + Σ_d log 2πσ²``
    (:func:`dtwin.hmm._log_emission`; variances at least the smallest normal float).
    """
    n_states, n_features = emission.shape[1], emission.shape[2]
    weights = np.empty((2 * n_features, n_states))
    constant = np.empty(n_states)
    quadratic = np.empty(n_features)
    for k in range(n_states):
        variances = np.maximum(emission[1, k], 2.2250738585072014e-308)
        for d in range(n_features):
            precision = 1.0 / variances[d]
            weights[d, k] = -2.0 * (emission[0, k, d] * precision)
            weights[n_features + d, k] = precision
            quadratic[d] = emission[0, k, d] ** 2 * precision
        constant[k] = _row_constant(quadratic, variances)
    return weights, constant


@njit(cache=True)
def _ar_weights(emission):
    """Weights (5D, K) of the rows ``(y, x, y², yx, x²)`` and the constant (K,) of ``−2 log N``.

    ``(−2c, 2cφ, 1, −2φ, φ²)/σ²`` and ``Σ_d c²/σ² + Σ_d log 2πσ²``
    (:func:`dtwin.hmm_ar._ar_log_emission`).
    """
    n_states, n_features = emission.shape[1], emission.shape[2]
    weights = np.empty((5 * n_features, n_states))
    constant = np.empty(n_states)
    quadratic = np.empty(n_features)
    for k in range(n_states):
        for d in range(n_features):
            c, phi, w = emission[0, k, d], emission[1, k, d], 1.0 / emission[2, k, d]
            weights[d, k] = -2.0 * c * w
            weights[n_features + d, k] = 2.0 * c * phi * w
            weights[2 * n_features + d, k] = w
            weights[3 * n_features + d, k] = -2.0 * phi * w
            weights[4 * n_features + d, k] = phi**2 * w
            quadratic[d] = c**2 * w
        constant[k] = _row_constant(quadratic, emission[2, k])
    return weights, constant


@njit(cache=True)
def _log_frameprob(kind, data, emission, out):
    """Emission log-densities ``log b_k(row_t)`` into ``out`` (T, K): one matrix product."""
    if kind == GAUSSIAN:
        weights, constant = _gaussian_weights(emission)
    else:
        weights, constant = _ar_weights(emission)
    np.dot(data, weights, out)
    for t in range(out.shape[0]):
        for k in range(out.shape[1]):
            out[t, k] = -0.5 * (out[t, k] + constant[k])


@njit(cache=True)
def _gaussian_mstep(occupancy, sums, var_floor):
    """Hmmlearn's diagonal M-step with the priors off: weighted means and variances (unfloored)."""
    n_states, n_features = occupancy.shape[0], sums.shape[1] // 2
    emission = np.empty((2, n_states, n_features))
    for k in range(n_states):
        denom = occupancy[k]
        for d in range(n_features):
            obs, obs2 = sums[k, d], sums[k, n_features + d]
            mean = obs / denom
            emission[0, k, d] = mean
            emission[1, k, d] = ((obs2 - 2.0 * mean * obs) + mean**2 * denom) / max(denom, 1e-5)
    return emission


@njit(cache=True)
def _ar_mstep(occupancy, sums, var_floor):
    """Weighted least squares of y on (1, x) per state and feature (``hmm_ar._ar_mstep``)."""
    n_states, n_features = occupancy.shape[0], sums.shape[1] // 5
    emission = np.empty((3, n_states, n_features))
    for k in range(n_states):
        n = max(occupancy[k], 2.2250738585072014e-308)
        for d in range(n_features):
            sy, sx = sums[k, d], sums[k, n_features + d]
            syy, sxy, sxx = (
                sums[k, 2 * n_features + d],
                sums[k, 3 * n_features + d],
                sums[k, 4 * n_features + d],
            )
            mean_x, mean_y = sx / n, sy / n
            var_x, var_y = sxx / n - mean_x**2, syy / n - mean_y**2
            cov = sxy / n - mean_x * mean_y
            coef = cov / var_x if var_x > 1e-12 * max(1.0, sxx / n) else 0.0
            emission[0, k, d] = mean_y - coef * mean_x
            emission[1, k, d] = coef
            emission[2, k, d] = max(var_y - coef * cov, var_floor)
    return emission


@njit(cache=True)
def _emission_mstep(kind, gamma, data, var_floor):
    occupancy, sums = _weighted_sums(gamma, data)
    if kind == GAUSSIAN:
        return _gaussian_mstep(occupancy, sums, var_floor)
    return _ar_mstep(occupancy, sums, var_floor)


@njit(cache=True)
def _floor_variances(emission, var_floor):
    last = emission.shape[0] - 1
    for k in range(emission.shape[1]):
        for d in range(emission.shape[2]):
            emission[last, k, d] = max(emission[last, k, d], var_floor)


@njit(cache=True)
def _finite(array):
    return np.isfinite(array).all()


@njit(cache=True)
def _stops(history, n_done, max_iter, tol):
    """depmixS4's rule after ``n_done`` iterations; returns (stop, stopped_by_tol)."""
    if n_done >= max_iter:
        return True, False
    if n_done >= 2 and history[n_done - 1] - history[n_done - 2] < tol * abs(history[n_done - 2]):
        return True, True
    return False, False


@njit(cache=True)
def _is_distribution(startprob, transmat):
    """Hmmlearn's ``_check``: π and every row of A sum to 1 (``np.allclose``)."""
    if abs(_numpy_sum(startprob) - 1.0) > 1e-8 + 1e-5:
        return False
    for i in range(transmat.shape[0]):
        if abs(_numpy_sum(transmat[i]) - 1.0) > 1e-8 + 1e-5:
            return False
    return True


@njit(cache=True)
def em(kind, data, emission, max_iter, tol, var_floor, log_space):
    """EM from one emission start (π, A uniform); the emission is Gaussian or AR(1) by ``kind``.

    Scaled recursions (:func:`_estep`; :data:`UNDERFLOW` where hmmlearn's would underflow) or,
    with ``log_space``, log-space ones (:func:`_estep_log`, hmmlearn's ``implementation="log"``;
    a non-finite log-likelihood is :data:`NON_FINITE`).
    Returns ``(code, history, stopped_by_tol, startprob, transmat, emission, final, γ)``.
    """
    n_steps, n_states = data.shape[0], emission.shape[1]
    startprob = np.full(n_states, 1.0 / n_states)
    transmat = np.full((n_states, n_states), 1.0 / n_states)
    buffers, xi = _lattices(n_steps, n_states), np.empty((n_states, n_states))
    history = np.empty(max_iter)
    n_done, stopped, code = 0, False, OK
    while True:
        if log_space:
            log_prob = _estep_log(kind, data, emission, startprob, transmat, buffers, xi)
        else:
            log_prob = _estep(kind, data, emission, startprob, transmat, buffers, xi)
            if math.isnan(log_prob):
                code = UNDERFLOW
                break
        gamma = buffers[_GAMMA]
        startprob, transmat = _transition_mstep(startprob, transmat, gamma, xi)
        emission = _emission_mstep(kind, gamma, data, var_floor)
        history[n_done] = log_prob
        n_done += 1
        if not (np.isfinite(log_prob) and _finite(emission) and _finite(transmat)):
            code = NON_FINITE
            break
        if not _finite(startprob):
            code = NON_FINITE
            break
        _floor_variances(emission, var_floor)
        stop, stopped = _stops(history, n_done, max_iter, tol)
        if stop:
            break
    final = math.nan
    if code == OK and not _is_distribution(startprob, transmat):
        code = NOT_DISTRIBUTION
    if code == OK and log_space:
        final = _estep_log(kind, data, emission, startprob, transmat, buffers, xi)
        code = OK if np.isfinite(final) else NON_FINITE
    elif code == OK:
        final = _estep(kind, data, emission, startprob, transmat, buffers, xi)
        code = UNDERFLOW if math.isnan(final) else OK
    gamma = buffers[_GAMMA]
    return code, history[:n_done].copy(), stopped, startprob, transmat, emission, final, gamma


@njit(cache=True)
def _viterbi_lattice(lattice, startprob, transmat):
    """Fill the Viterbi lattice in place (it enters holding log b); returns log A."""
    n_steps, n_states = lattice.shape
    log_start, log_trans = np.log(startprob), np.log(transmat)
    for i in range(n_states):
        lattice[0, i] += log_start[i]
    for t in range(1, n_steps):
        for i in range(n_states):
            best = -np.inf
            for j in range(n_states):
                value = lattice[t - 1, j] + log_trans[j, i]
                if best < value:
                    best = value
            lattice[t, i] = best + lattice[t, i]
    return log_trans


@njit(cache=True)
def viterbi(kind, data, emission, startprob, transmat):
    """Viterbi path (Eq. (10)) with hmmlearn's arithmetic and tie-breaking.

    The last state is the first maximum of the final column; going back, a tie goes to the
    later state (hmmlearn's ``std::max`` over ``(score, state)`` pairs).
    """
    n_steps, n_states = data.shape[0], emission.shape[1]
    lattice = np.empty((n_steps, n_states))
    _log_frameprob(kind, data, emission, lattice)
    log_trans = _viterbi_lattice(lattice, startprob, transmat)
    path = np.empty(n_steps, dtype=np.int64)
    state = 0
    for i in range(1, n_states):
        if lattice[n_steps - 1, state] < lattice[n_steps - 1, i]:
            state = i
    path[n_steps - 1] = state
    for t in range(n_steps - 2, -1, -1):
        best, best_state = -np.inf, 0
        for i in range(n_states):
            value = lattice[t, i] + log_trans[i, state]
            if best < value or (not value < best and best_state < i):
                best, best_state = value, i
        state = best_state
        path[t] = state
    return path


@njit(cache=True)
def score(kind, data, emission, startprob, transmat):
    """Log p(rows) by the scaled forward pass, or the log-space one where that underflows."""
    n_steps, n_states = data.shape[0], emission.shape[1]
    frameprob, fwd = np.empty((n_steps, n_states)), np.empty((n_steps, n_states))
    _log_frameprob(kind, data, emission, frameprob)
    _exp_all(frameprob)
    log_prob = _forward(startprob, transmat, frameprob, fwd, np.empty(n_steps))
    if math.isnan(log_prob):
        _log_frameprob(kind, data, emission, frameprob)
        log_trans_t = np.ascontiguousarray(np.log(transmat).T)
        log_prob = _log_forward(np.log(startprob), log_trans_t, frameprob, fwd)
    return log_prob


def warm_up() -> None:
    """Compile every kernel for the argument types dtwin passes, or load it from the cache.

    ``make venv`` runs this once, so no pipeline job pays the compilation (~20 s). The types:
    ``kind`` an int, rows ``(T, C)``, emissions ``(P, K, D)``, π ``(K,)`` and A ``(K, K)``,
    all float64, C-contiguous and writable; ``max_iter`` an int, ``tol`` and ``var_floor``
    floats.
    """
    rng = np.random.default_rng(0)
    X = rng.normal(size=(12, 2))
    startprob, transmat = np.full(2, 0.5), np.full((2, 2), 0.5)
    cases = (
        (GAUSSIAN, np.hstack((X, X * X)), np.stack((rng.normal(size=(2, 2)), np.ones((2, 2))))),
        (
            AR1,
            np.hstack((X[1:], X[:-1], X[1:] ** 2, X[1:] * X[:-1], X[:-1] ** 2)),
            np.ones((3, 2, 2)),
        ),
    )
    with subnormals_flushed():
        for kind, data, emission in cases:
            for log_space in (False, True):
                em(kind, data, emission, 2, 1e-8, 1e-3, log_space)
            viterbi(kind, data, emission, startprob, transmat)
            score(kind, data, emission, startprob, transmat)
