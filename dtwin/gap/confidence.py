"""The answer's confidence: its BIC weight mapped to a probability of being right.

Specification: docs/gap.md §Confidence.

The winner's BIC weight among its module's candidates (:func:`dtwin.gap.diagnose`) says how
much better it scores than the other candidates, not how often such an answer is right: on
the full benchmark 590 of 639 named answers had a weight of 1.00 and were right 96 % of the
time, and answers near 0.68 were right 47 % of the time. :func:`calibrated_confidence` maps the
weight through a **monotone step function** (:data:`STEPS`) fitted by :func:`fit_steps`
(isotonic regression: pool adjacent violators, equal weights pooled) on the benchmark answers
of one set of seeds and checked on a disjoint set (docs/gap.md §Confidence gives both).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["STEPS", "WEIGHT_CLIP", "calibrated_confidence", "fit_steps"]

#: Weights are clipped to ``[WEIGHT_CLIP, 1 − WEIGHT_CLIP]`` (a weight of exactly 1 in floating
#: point carries no more evidence than 1 − 1e-9: all such answers are one group).
WEIGHT_CLIP = 1e-9
#: ``(lowest weight, probability)`` of each step, by rising weight: fitted by :func:`fit_steps`
#: on the named answers of the benchmark's cases 00–04 (335 answers; the steps held 8, 60 and
#: 267 of them), docs/gap.md §Confidence.
STEPS: tuple[tuple[float, float], ...] = (
    (0.0, 0.5),
    (0.781721, 0.883333),
    (1.0 - WEIGHT_CLIP, 0.981273),
)


def calibrated_confidence(weight: float, steps: Sequence[tuple[float, float]] = STEPS) -> float:
    """Return the probability that an answer of BIC weight ``weight`` is right.

    Parameters
    ----------
    weight : float in [0, 1]
        The chosen candidate's BIC weight.
    steps : sequence of (float, float), default :data:`STEPS`
        ``(lowest weight, probability)`` by rising weight; a weight below the first step's
        gets the first step's probability.

    Returns
    -------
    float in [0, 1]

    Examples
    --------
    >>> calibrated_confidence(0.9, [(0.0, 0.5), (0.8, 0.9)])
    0.9
    """
    w = min(max(float(weight), WEIGHT_CLIP), 1.0 - WEIGHT_CLIP)
    probability = steps[0][1]
    for lowest, value in steps:
        if w >= lowest:
            probability = value
    return float(probability)


def fit_steps(
    weights: Sequence[float], rights: Sequence[bool]
) -> tuple[tuple[float, float, int], ...]:
    """Return the isotonic step map of ``rights`` on ``weights``: ``(lowest, probability, n)``.

    Pool adjacent violators over the distinct (clipped) weights, each weight's answers pooled
    first; every step is the share right among its ``n`` answers, rising with the weight.

    Parameters
    ----------
    weights : sequence of float
        BIC weights of answers that name an effect.
    rights : sequence of bool
        Whether each answer was right (module and effect).

    Returns
    -------
    tuple of (float, float, int)

    Examples
    --------
    >>> fit_steps([0.6, 0.7, 0.9, 1.0], [True, False, True, True])
    ((0.6, 0.5, 2), (0.9, 1.0, 2))
    """
    w = np.clip(np.asarray(weights, dtype=float), WEIGHT_CLIP, 1.0 - WEIGHT_CLIP)
    y = np.asarray(rights, dtype=float)
    if len(w) != len(y) or not len(w):
        raise ValueError(f"weights and rights must have one length >= 1 (got {len(w)}, {len(y)})")
    blocks: list[list[float]] = []  # [right, count, lowest weight]
    for level in np.unique(w):
        at = w == level
        blocks.append([float(y[at].sum()), float(at.sum()), float(level)])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] >= blocks[-1][0] / blocks[-1][1]:
            right, count, _ = blocks.pop()
            blocks[-1][0] += right
            blocks[-1][1] += count
    return tuple((low, right / count, int(count)) for right, count, low in blocks)
