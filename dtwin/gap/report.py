"""Reports of a diagnosis: ``diagnosis.json``, ``report.md`` and a figure.

Specification: docs/gap.md §Output files.

:func:`diagnosis_to_dict` gives the JSON payload (schema: ``workflow/schemas/
diagnosis.schema.json``); :func:`write_report` writes all three files into a folder, each
atomically. The figure answers in one look: where the gap lies (local vs chain gap per module
against its noise threshold), the ranked candidates, and the source module before/after on the
scoring part. The three shrinks are defined once, in :data:`DEFINITIONS` (docs/gap.md §How far).
"""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dtwin.artifacts import atomic_write, to_jsonable, write_json
from dtwin.gap.effects import NONE, UNEXPLAINED, effect_by_name
from dtwin.gap.results import Diagnosis
from dtwin.gap.which import required_share
from dtwin.twin.wiring import PLANT, only_module

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "SCHEMA_VERSION",
    "DEFINITIONS",
    "SHRINKS",
    "diagnosis_to_dict",
    "render_markdown",
    "write_report",
]

SCHEMA_VERSION = "dtwin.gap/2"

#: How every number of the report is defined (copied into ``diagnosis.json``).
DEFINITIONS: dict[str, str] = {
    "parts": "the recording is cut in three: the training part (the first train_frac of the "
    "samples: every parameter is fitted there), the choosing part (the next choose_frac of the "
    "rest: every decision, i.e. where the gap lies, which candidate, unexplained) and the "
    "scoring part (the remaining samples, or the --heldout recording: every gap after an "
    "effect and every shrink). No reported shrink is measured on data used for a decision",
    "gap": "normalised RMS error over a part: RMS(recorded − twin) / std(recorded signal over "
    "the whole recording)",
    "local gap": "the module's twin driven with the module's recorded input",
    "chain gap": "the whole twin run from the most upstream recorded signal, each module fed by "
    "its simulated predecessor (scoring part)",
    "noise_floor": "the gap the module's own noise explains (twin noise levels; from the data "
    "when the twin gives none); one floor per module, the same for every candidate",
    "threshold": "noise floor × (1 + noise_tolerance) × the upper (1 − significance) quantile of "
    "a noise RMS over the effective sample size before the scoring part; the excess over the "
    "floor must reach min_gap",
    "gap_before, gap_calibrated": "the twin's local gap (choosing part), and the gap after "
    "re-fitting the module's linear parameters within calibration_tolerance of nominal on the "
    "training part (calibration slack removed; training and choosing parts): it decides where "
    "the gap lies",
    "excess gap": "sqrt(max(gap² − noise_floor², 0)): the part of the gap above what noise "
    "explains",
    "raw_shrink_pct": "shrink 1 of 3, the whole error: 100·(1 − gap_after / gap_before) of the "
    "source module on the scoring part",
    "own_shrink_pct": "shrink 2 of 3, the effect's own share (the headline): 100·(1 − excess "
    "gap after / excess gap of gap_refit), gap_refit being the twin with only its linear "
    "parameters re-fitted on the same training part (every effect fit re-fits them too, so "
    "this is what the effect adds to that re-fit); for parameter_mismatch, which is that "
    "re-fit, the reference is the twin as given. Scoring part",
    "excess_shrink_pct": "shrink 3 of 3, the excess over the noise floor: 100·(1 − excess gap "
    "after / excess gap before), the module's one noise floor for every candidate; "
    "excess_clipped is true when the gap after is within the floor (the shrink is then "
    "exactly 100 %). Scoring part",
    "kpi_shrink_pct": "100·(1 − chain gap after / chain gap before) of the end-to-end signal "
    "(kpi_signal: z when recorded), scoring part; null when the source is not upstream of it",
    "choosing_share_pct": "the excess gap a candidate removes on the choosing part (on the "
    "training and choosing parts when the twin has no excess on the choosing part), against its "
    "own floor (a quantizer's includes its rounding); the winner needs min_share of it "
    "(min_linear_share for a candidate of linear form: parameter_mismatch, sensor_scale_error)",
    "score": "n_eff·deviance + n_params·ln(n_eff) on the choosing part (deviance ln MSE; a "
    "quantizer's its own density's), relative to the best candidate",
    "confidence": "the probability that the answer (module and effect) is right: the chosen "
    "candidate's BIC weight among its module's candidates (bic_weight) mapped by an isotonic "
    "step function fitted on the benchmark's answers of one set of seeds and checked on a "
    "disjoint set "
    "(docs/gap.md §Confidence): of answers given confidence 0.9, about 9 in 10 were right there",
    "bic_weight": "BIC weight of the chosen candidate among the module's candidates, "
    "exp(−score/2) normalised: how much better it scores than the others, not how often it is "
    "right",
    "param_intervals": "95 % interval [low, high] of each fitted parameter of the answer "
    "(shown after its value in the first line of report.md): the least-squares fit's sandwich "
    "covariance with the training residuals cut in 20 blocks taken as independent, and a t "
    "quantile with 19 degrees of freedom; widened by the spread between the fits on the training "
    "and choosing parts, by the difference from a wider catalogue form that nests the answer's "
    "(Coulomb friction: Stribeck friction's Fc), down to the largest output of a saturation the "
    "recorded inputs reach, and never narrower than the fit's step tolerance "
    "(docs/gap.md §Intervals)",
    "free_run_rms_before, free_run_rms_after": "RMS of recorded − simulated output of the "
    "source module (M1 when the answer is none) over the scoring part, in the recording's units, "
    "the twin run freely from the recorded state at the scoring part's first sample: with the "
    "linear twin (calibrated, or the twin file's) and with the chosen effect; null for a plant "
    "that is not strictly stable (integrating: its free run drifts with any force error) and "
    "after, when no effect is chosen",
}

#: The three shrinks (``Diagnosis`` field, short label), the effect's own share first.
SHRINKS: tuple[tuple[str, str], ...] = (
    ("own_shrink_pct", "effect's own share"),
    ("raw_shrink_pct", "raw error"),
    ("excess_shrink_pct", "excess over noise"),
)


def diagnosis_to_dict(diagnosis: Diagnosis) -> dict[str, Any]:
    """Return the JSON payload of a diagnosis (plain types, non-finite numbers as null)."""
    modules = {}
    for name, report in diagnosis.modules.items():
        entry = asdict(report)
        entry.pop("name")
        entry["nominal"] = entry.pop("lin_nominal")
        entry["used"] = entry.pop("lin_used")
        modules[name] = entry
    candidates = []
    for candidate in diagnosis.candidates:
        entry = asdict(candidate)
        entry["linear_params"] = entry.pop("lin")
        candidates.append(entry)
    d = diagnosis
    payload = {
        "schema": SCHEMA_VERSION,
        "module": d.module,
        "effect": d.effect,
        "params": d.params,
        "param_intervals": {name: list(bounds) for name, bounds in d.param_intervals.items()},
        "confidence": d.confidence,
        "bic_weight": d.bic_weight,
        **{key: getattr(d, key) for key in ("gap_before", "gap_refit", "gap_after")},
        "shrink_pct": d.shrink_pct,
        **{key: getattr(d, key) for key, _ in SHRINKS},
        "excess_clipped": d.excess_clipped,
        "kpi_shrink_pct": d.kpi_shrink_pct,
        "kpi_signal": d.kpi_signal,
        "free_run_rms_before": d.free_run_rms_before,
        "free_run_rms_after": d.free_run_rms_after,
        "modules": modules,
        "candidates": candidates,
        "recording": {
            "n_samples": d.n_samples,
            "n_train": d.n_train,
            "n_choose": d.n_choose,
            "dt": d.dt,
            "train_frac": d.train_frac,
        },
        "calibrated": list(d.calibrated),
        "twin_discretisation": d.twin_discretisation,
        "also_needed": [dict(entry) for entry in d.also_needed],
        "notes": list(d.notes),
        "settings": asdict(d.settings),
        "definitions": DEFINITIONS,
    }
    return to_jsonable(payload)


def _fmt(value: Any, digits: int = 3) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def _unexplained_headline(d: Diagnosis) -> str:
    """Return the first line of an ``unexplained`` answer: the closest candidate and its bar."""
    own = [c for c in d.candidates if c.module == d.module]
    if not own:
        return f"**Gap in {d.module}, unexplained**: the module has no candidate effect."
    best = min(own, key=lambda c: c.score)
    needed = required_share(best.effect, d.settings)
    kind = "linear-form " if effect_by_name(best.effect).linear_form else ""
    return (
        f"**Gap in {d.module}, unexplained**: the best-scored candidate, {best.effect}, removes "
        f"{best.choosing_share_pct:.0f} % of the excess gap on the choosing part; a "
        f"{kind}candidate must remove {needed:.0%} to explain it."
    )


def _also_needed_line(d: Diagnosis) -> str:
    """Return the sentence naming the other modules with a gap of their own ('' if none)."""
    if not d.also_needed:
        return ""
    parts = []
    for other in d.also_needed:
        share = other["choosing_share_pct"]
        removes = "" if share is None else f", its best candidate removes {share:.0f} %"
        parts.append(f"{other['module']}: {other['effect']}{removes}")
    return (
        f" **A second effect is needed**: {'; '.join(parts)} (a gap beyond its own noise "
        "threshold; the answer above is the module furthest above its threshold)."
    )


def _headline(d: Diagnosis) -> str:
    if d.effect == NONE:
        return "**No gap beyond the noise**: every diagnosed module is within its noise threshold."
    return _answer_headline(d) + _also_needed_line(d)


def _param_text(name: str, value: float, bounds: tuple[float, float] | None) -> str:
    """Return ``name = value [low, high]`` (the 95 % interval when there is one)."""
    interval = f" [{bounds[0]:.4g}, {bounds[1]:.4g}]" if bounds is not None else ""
    return f"{name} = {value:.4g}{interval}"


def _answer_headline(d: Diagnosis) -> str:
    if d.effect == UNEXPLAINED:
        return _unexplained_headline(d)
    params = ", ".join(_param_text(k, v, d.param_intervals.get(k)) for k, v in d.params.items())
    kpi = (
        f"; end-to-end {d.kpi_signal} gap −{d.kpi_shrink_pct:.0f} %"
        if d.kpi_shrink_pct is not None
        else ""
    )
    clipped = " (clipped: the gap after is within the noise floor)" if d.excess_clipped else ""
    return (
        f"**Gap in {d.module}: {d.effect}** ({params}; confidence {d.confidence:.2f}: the "
        "share of the benchmark's answers of this confidence that were right). "
        f"On the scoring part, it removes {d.own_shrink_pct:.0f} % of the excess gap left by "
        f"re-fitting the linear parameters alone (its own share); whole error "
        f"{d.gap_before:.3g} → {d.gap_after:.3g} (−{d.raw_shrink_pct:.0f} %); excess over the "
        f"noise floor −{d.excess_shrink_pct:.0f} %{clipped}{kpi}."
    )


def _free_run_lines(d: Diagnosis) -> list[str]:
    """Return the report's free-run sentence and a blank line ([] when there is none)."""
    if d.free_run_rms_before is None:
        return []
    module = d.module or only_module(PLANT)
    after = (
        f" → {d.free_run_rms_after:.4g} with the effect" if d.free_run_rms_after is not None else ""
    )
    return [
        f"Free run of {module} over the scoring part from its first sample (recording units, "
        f"comparable to published simulation errors): RMS {d.free_run_rms_before:.4g} with the "
        f"linear twin{after}.",
        "",
    ]


def render_markdown(diagnosis: Diagnosis, figure_name: str | None = "gap.png") -> str:
    """Return ``report.md``: the answer first, then per-module gaps, candidates, definitions.

    ``figure_name`` None: no figure to link.
    """
    d = diagnosis
    lines = [
        "# Sim-to-real gap diagnosis",
        "",
        _headline(d),
        "",
        *([f"![gap diagnosis]({figure_name})", ""] if figure_name else []),
        f"Recording: {d.n_samples} samples, dt = {d.dt:.6g} s; parameters fitted on the first "
        f"{d.n_train} samples ({d.train_frac:.0%}, training part), decisions taken on the next "
        f"{d.n_choose - d.n_train} (choosing part), every shrink measured on the remaining "
        f"{d.n_samples - d.n_choose} (scoring part).",
        "",
        *_free_run_lines(d),
        "## Where: per module",
        "",
        "| module | status | local gap (choosing) | after calibration slack | threshold "
        "| gap (scoring) | after linear re-fit | after effect | chain gap | why |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, m in d.modules.items():
        lines.append(
            f"| {name} | {m.status} | {_fmt(m.gap_before)} | {_fmt(m.gap_calibrated)} "
            f"| {_fmt(m.threshold)} | {_fmt(m.scoring_gap_before)} | {_fmt(m.scoring_gap_refit)} "
            f"| {_fmt(m.scoring_gap_after)} | {_fmt(m.chain_gap)} | {m.reason} |"
        )
    lines += ["", "## Which: candidates (score on the choosing part, best first)", ""]
    if d.candidates:
        lines += [
            "| module | effect | parameters | share removed (choosing) % | score | weight "
            "| gap after (scoring) | own share % | raw % | excess % |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for c in d.candidates:
            params = ", ".join(f"{k}={v:.4g}" for k, v in c.params.items())
            lines.append(
                f"| {c.module} | {c.effect} | {params} | {_fmt(c.choosing_share_pct)} "
                f"| {c.score:.1f} | {c.weight:.2f} | {_fmt(c.scoring_gap_after)} "
                f"| {_fmt(c.own_shrink_pct)} | {_fmt(c.raw_shrink_pct)} "
                f"| {_fmt(c.excess_shrink_pct)}{'*' if c.excess_clipped else ''} |"
            )
        lines += ["", "\\* clipped: the gap after is within the noise floor."]
    else:
        lines.append("No module has a gap beyond its noise, so no candidate was fitted.")
    if d.notes:
        lines += ["", "## Notes", ""] + [f"- {note}" for note in d.notes]
    lines += ["", "## Definitions", ""] + [f"- **{k}**: {v}" for k, v in DEFINITIONS.items()]
    return "\n".join(lines) + "\n"


#: ``gap.png``'s resolution, dots per inch: 1500 x 420 pixels for the figure's 15 x 4.2 inches.
GAP_PNG_DPI = 100


def _draw_figure(d: Diagnosis, paths: list[Path]) -> None:
    """Draw ``gap.png`` to ``paths``: where (local vs chain gap), which (candidates), how far.

    In matplotlib's default style at :data:`GAP_PNG_DPI`, whatever style the process set before
    (the paper figures' :func:`dtwin.figures._style.apply_style` sets 300 dpi and print-size
    fonts), so the report looks the same from the CLI and from any other caller. Laid out once
    (``tight_layout``) and saved at the figure's own size: one draw, no second one to crop.
    """
    import matplotlib.pyplot as plt

    from dtwin.figures._style import save_figure

    with plt.style.context("default"):
        fig = _gap_figure(d)
        fig.tight_layout()
        save_figure(fig, paths, tight=False, dpi=GAP_PNG_DPI)


def _gap_figure(d: Diagnosis) -> Figure:
    """Return ``gap.png``'s figure (three panels and a title), drawn in the current style."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), gridspec_kw={"width_ratios": [1.2, 1, 1.6]})
    names = [n for n, m in d.modules.items() if m.status != "skipped"]
    x = np.arange(len(names))
    local = [d.modules[n].gap_before for n in names]
    chain = [d.modules[n].chain_gap or 0.0 for n in names]
    thresholds = [d.modules[n].threshold for n in names]
    ax = axes[0]
    colors = ["tab:red" if d.modules[n].status in ("source", "gap") else "tab:blue" for n in names]
    ax.bar(x - 0.2, local, 0.4, color=colors, label="local gap")
    ax.bar(x + 0.2, chain, 0.4, color="lightgray", label="chain gap")
    ax.scatter(x - 0.2, thresholds, marker="_", s=400, color="k", label="noise threshold")
    ax.set_xticks(x, names)
    ax.set_ylabel("normalised RMS gap (held-out)")
    ax.set_title("Where: local gap vs chain gap")
    ax.legend(fontsize=8)
    ax = axes[1]
    if d.candidates:
        labels = [f"{c.module} {c.effect}" for c in d.candidates][::-1]
        values = [c.choosing_share_pct for c in d.candidates][::-1]
        values = [v if np.isfinite(v) else -100.0 for v in values]
        bar_colors = ["tab:green" if c.effect == d.effect else "gray" for c in d.candidates][::-1]
        ax.barh(labels, np.clip(values, -100, 100), color=bar_colors)
        ax.axvline(100 * d.settings.min_share, color="k", ls="--", lw=1)
        ax.set_xlabel("excess gap removed on the choosing part, %")
        ax.tick_params(axis="y", labelsize=8)
    else:
        ax.text(0.5, 0.5, "no gap beyond noise:\nno candidates", ha="center", va="center")
        ax.set_axis_off()
    ax.set_title("Which: candidates")
    ax = axes[2]
    if d.series:
        t, recorded = d.series["t"], d.series["recorded"]
        after_label = "twin + effect" if d.effect != UNEXPLAINED else "twin + best candidate"
        ax.plot(t, recorded - d.series["before"], color="tab:red", lw=0.8, label="recorded − twin")
        if "after" in d.series:  # no candidate (a calibrated M3 or M4): nothing to add
            ax.plot(
                t,
                recorded - d.series["after"],
                color="tab:green",
                lw=0.8,
                label=f"recorded − ({after_label})",
            )
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("t (s), scoring part")
        ax.set_ylabel(f"{d.module} output error (recording units)")
        ax.legend(fontsize=8)
    else:
        ax.set_axis_off()
    ax.set_title("How far: before / after")
    title = {NONE: "No gap beyond noise", UNEXPLAINED: f"{d.module}: unexplained gap"}.get(
        d.effect,
        f"{d.module}: {d.effect}, own share {(d.own_shrink_pct or 0):.0f} % "
        "(excess gap beyond a linear re-fit removed, scoring part)",
    )
    fig.suptitle(title, fontsize=13, fontweight="bold")
    return fig


def write_report(
    diagnosis: Diagnosis, out_dir: str | os.PathLike, *, figure: bool = True
) -> list[Path]:
    """Write ``diagnosis.json``, ``report.md`` and ``gap.png`` into ``out_dir``; return paths.

    ``figure=False`` leaves out ``gap.png`` (and ``report.md``'s link to it): the benchmark
    reads ``diagnosis.json`` only, and drawing the figure took half of a case's diagnosis.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path, png_path = out / "diagnosis.json", out / "report.md", out / "gap.png"
    write_json(diagnosis_to_dict(diagnosis), json_path)
    text = render_markdown(diagnosis, png_path.name if figure else None)
    atomic_write(md_path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    if not figure:
        return [json_path, md_path]
    _draw_figure(diagnosis, [png_path])
    return [json_path, md_path, png_path]
