"""The diagnoser's settings and results: :class:`GapSettings` in, :class:`Diagnosis` out.

A :class:`Diagnosis` is the content of ``diagnosis.json`` (docs/gap.md §Interface); it holds one
:class:`ModuleReport` per module of the wiring table (§Where) and one :class:`CandidateReport` per
fitted candidate (§Which, §How far). :class:`GapSettings` is the ``gap.diagnose`` config section's
decision constants (§Settings).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dtwin._validation import DtwinValueError, require_in_range

__all__ = ["GapSettings", "ModuleReport", "CandidateReport", "Diagnosis"]


@dataclass(frozen=True)
class GapSettings:
    """Decision constants of the diagnoser (the ``gap.diagnose`` config section).

    See docs/gap.md §Settings; their roles in §Where and §Which.

    Attributes
    ----------
    noise_tolerance : float, default 0.10
        Relative uncertainty of the twin's noise levels.
    calibration_tolerance : float, default 0.05
        Relative band around each nominal linear parameter that counts as "calibrated"
        (a bias's band is this fraction of the output's standard deviation).
    significance : float, default 0.01
        Probability that noise alone exceeds the threshold (a one-sided test).
    min_gap : float, default 0.005
        Smallest normalised excess gap (``√(gap² − floor²)``) worth reporting, whatever the
        noise.
    min_share : float, default 0.5
        Share of the choosing part's excess gap the best candidate must remove to explain it.
    min_linear_share : float, default 0.75
        The same for a candidate of linear form (``parameter_mismatch``, a sensor gain): the
        twin re-fitted inside its own model class is exact when such a candidate is the answer,
        so it leaves little but noise (right answers of the arms' benchmark seeds removed
        75.5–100 %, n = 72; backlash or hysteresis read as one removed 50–75 %, docs/gap.md
        §Which).
    choose_frac : float, default 0.5
        Share of the samples after the training part that is the **choosing part** (every
        decision: where, which, ``unexplained``); the rest is the **scoring part** (every
        reported gap after an effect and every shrink). Ignored with a separate held-out
        recording: that recording is the scoring part, the samples of the first recording after
        its training part the choosing part (docs/gap.md §Interface).
    """

    noise_tolerance: float = 0.10
    calibration_tolerance: float = 0.05
    significance: float = 0.01
    min_gap: float = 0.005
    min_share: float = 0.5
    min_linear_share: float = 0.75
    choose_frac: float = 0.5

    def __post_init__(self) -> None:
        require_in_range("gap.noise_tolerance", self.noise_tolerance, 0.0, 1.0)
        require_in_range("gap.calibration_tolerance", self.calibration_tolerance, 0.0, 1.0)
        require_in_range("gap.significance", self.significance, 1e-9, 0.5)
        require_in_range("gap.min_gap", self.min_gap, 0.0, 1.0)
        require_in_range("gap.min_share", self.min_share, 0.0, 1.0)
        require_in_range("gap.min_linear_share", self.min_linear_share, 0.0, 1.0)
        require_in_range("gap.choose_frac", self.choose_frac, 0.1, 0.9)

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any] | None) -> GapSettings:
        """Return settings from a mapping of the attribute names (missing keys keep defaults)."""
        mapping = dict(mapping or {})
        unknown = sorted(set(mapping) - set(cls.__dataclass_fields__))
        if unknown:
            raise DtwinValueError(f"gap.diagnose has unknown key(s): {', '.join(unknown)}")
        return cls(**{k: float(v) for k, v in mapping.items()})


@dataclass(frozen=True)
class ModuleReport:
    """What the diagnoser found for one module (gaps normalised as in :mod:`~dtwin.gap.localise`).

    ``gap_calibrated``, ``threshold`` and ``n_eff`` are measured on the training and the
    choosing part together (they decide where the gap lies), ``gap_before`` on the choosing
    part (candidates' shares start from it); ``scoring_gap_before``,
    ``scoring_gap_refit`` (the twin with only its linear parameters re-fitted, source module
    only), ``scoring_gap_after`` (with the chosen effect), ``chain_gap`` and
    ``chain_gap_after`` on the scoring part (docs/gap.md §How far).
    """

    name: str
    status: str
    reason: str
    calibrated: bool = False
    gap_before: float | None = None
    gap_calibrated: float | None = None
    scoring_gap_before: float | None = None
    scoring_gap_refit: float | None = None
    scoring_gap_after: float | None = None
    chain_gap: float | None = None
    chain_gap_after: float | None = None
    noise_floor: float | None = None
    noise_floor_twin: float | None = None
    noise_floor_data: float | None = None
    threshold: float | None = None
    n_eff: float | None = None
    lin_nominal: dict[str, float] | None = None
    lin_used: dict[str, float] | None = None
    discretisation: str | None = None
    horizon_samples: int | None = None
    reference_gap: float | None = None
    discretisation_training_gap: dict[str, float] | None = None


@dataclass(frozen=True)
class CandidateReport:
    """One fitted candidate: chosen on the choosing part, scored on the scoring part.

    ``choosing_gap``, ``choosing_share_pct`` (excess removed, against the candidate's own
    floor), ``score`` and ``weight`` come from the choosing part; ``scoring_gap_after`` and the
    three shrinks (``raw_shrink_pct``, ``own_shrink_pct``, ``excess_shrink_pct`` with
    ``excess_clipped``) from the scoring part (docs/gap.md §Which, §How far).
    """

    module: str
    effect: str
    params: dict[str, float]
    lin: dict[str, float]
    n_params: int
    choosing_gap: float
    choosing_share_pct: float
    scoring_gap_after: float
    raw_shrink_pct: float
    own_shrink_pct: float
    excess_shrink_pct: float
    excess_clipped: bool
    score: float
    weight: float


@dataclass(frozen=True)
class Diagnosis:
    """The diagnosis of one recording (the content of ``diagnosis.json``).

    ``module`` is the source module or None; ``effect`` an effect name, ``"none"`` or
    ``"unexplained"``. The three shrinks (docs/gap.md §How far) are percentages on the scoring
    part, None when no effect was added: ``raw_shrink_pct`` (whole error, ``gap_before`` →
    ``gap_after``), ``own_shrink_pct`` (the effect's own share: excess of the twin with only
    its linear parameters re-fitted, ``gap_refit``, → ``gap_after``) and ``excess_shrink_pct``
    (excess over the module's one noise floor; ``excess_clipped`` when the gap after is within
    the floor, i.e. 100 %). ``also_needed`` lists the other modules with a gap of their own
    (:func:`~dtwin.gap.which.other_gaps`: a second effect is needed). ``twin_discretisation``
    is the plant's discretisation the twin declares (None: chosen on the training part; the one
    used is ``modules["M1"].discretisation``). ``series`` holds scoring-part time series of the
    source module for the figure. ``free_run_rms_before`` and ``free_run_rms_after`` are RMS errors
    in the recording's units of the source module (M1 when there is none) simulated over the
    scoring part from its first sample, with the linear twin and with the chosen effect
    (:func:`~dtwin.gap.how_far.free_run_rms`; None for an integrating or unstable plant).
    ``param_intervals`` gives a 95 % interval of every fitted parameter of the answer
    (:func:`~dtwin.gap.how_far.answer_intervals`).
    ``confidence`` is the probability that the answer is right, the winner's ``bic_weight``
    mapped by :func:`dtwin.gap.confidence.calibrated_confidence`.
    """

    module: str | None
    effect: str
    params: dict[str, float]
    confidence: float | None
    gap_before: float | None
    gap_refit: float | None
    gap_after: float | None
    raw_shrink_pct: float | None
    own_shrink_pct: float | None
    excess_shrink_pct: float | None
    excess_clipped: bool | None
    kpi_shrink_pct: float | None
    kpi_signal: str | None
    modules: dict[str, ModuleReport]
    candidates: list[CandidateReport]
    n_samples: int
    n_train: int
    n_choose: int
    dt: float
    train_frac: float
    calibrated: tuple[str, ...]
    notes: tuple[str, ...]
    settings: GapSettings
    also_needed: tuple[dict[str, Any], ...] = ()
    twin_discretisation: str | None = None
    free_run_rms_before: float | None = None
    free_run_rms_after: float | None = None
    param_intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    bic_weight: float | None = None
    series: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def shrink_pct(self) -> float | None:
        """The headline shrink: ``own_shrink_pct`` (``shrink_pct`` of ``dtwin.gap/1`` readers)."""
        return self.own_shrink_pct
