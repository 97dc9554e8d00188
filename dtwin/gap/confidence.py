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

__all__ = [
    "STEPS",
    "FITTING_CASES",
    "WEIGHT_CLIP",
    "MIN_STEP_ANSWERS",
    "calibrated_confidence",
    "fit_steps",
]

#: Weights are clipped to ``[WEIGHT_CLIP, 1 − WEIGHT_CLIP]`` (a weight of exactly 1 in floating
#: point carries no more evidence than 1 − 1e-9: all such answers are one group).
WEIGHT_CLIP = 1e-9
#: ``(lowest weight, probability)`` of each step, by rising weight: fitted by :func:`fit_steps`
#: on the named answers of the benchmark's cases 00–04 (348 answers; the steps held 10, 80 and
#: 258 of them), docs/gap.md §Confidence.
STEPS: tuple[tuple[float, float], ...] = (
    (0.0, 0.6),
    (0.776877, 0.95),
    (1.0 - WEIGHT_CLIP, 0.980620),
)
#: The benchmark case numbers (``NN`` of a case ``<type>_NN``, its seed's offset) whose answers
#: :data:`STEPS` was fitted on; the others check it (:mod:`dtwin.gapbench.scores`).
FITTING_CASES: frozenset[int] = frozenset(range(5))


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


#: Fewest answers of a step: a smaller one joins its neighbour above (the top one, below). A
#: step of one wrong answer read 0.0 for every weight under it.
MIN_STEP_ANSWERS = 10


def fit_steps(
    weights: Sequence[float], rights: Sequence[bool], min_answers: int = MIN_STEP_ANSWERS
) -> tuple[tuple[float, float, int], ...]:
    """Return the isotonic step map of ``rights`` on ``weights``: ``(lowest, probability, n)``.

    Pool adjacent violators over the distinct (clipped) weights, each weight's answers pooled
    first; then a step of fewer than ``min_answers`` answers joins its neighbour above (the top
    step its neighbour below), which keeps the map rising. Every step is the share right among
    its ``n`` answers.

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
    >>> fit_steps([0.6, 0.7, 0.9, 1.0], [True, False, True, True], min_answers=1)
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
    while len(blocks) > 1 and min(b[1] for b in blocks) < min_answers:
        index = next(i for i, b in enumerate(blocks) if b[1] < min_answers)
        into = index + 1 if index + 1 < len(blocks) else index - 1
        low, high = sorted((index, into))
        blocks[low] = [
            blocks[low][0] + blocks[high][0],
            blocks[low][1] + blocks[high][1],
            blocks[low][2],
        ]
        del blocks[high]
    return tuple((low, right / count, int(count)) for right, count, low in blocks)
