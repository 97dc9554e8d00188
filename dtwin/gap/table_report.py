"""The files of a diagnosis against a twin table: ``diagnosis.json``, ``report.md``, ``gap.png``.

Specification: docs/gap.md §Twin file (the answer) and §Output files. The JSON holds the answer
(``module``, ``modules``, ``effect``, ``at``, ``params`` and their 95 % intervals, the
combinations of params the data cannot separate), the gaps and shrinks on the scoring part, each
unit's twin, floor and threshold, and every fitted candidate; ``schema`` is
:data:`TABLE_SCHEMA`.
"""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import Any

from dtwin.artifacts import atomic_write, to_jsonable, write_json
from dtwin.gap.table_diagnose import TableDiagnosis

__all__ = ["TABLE_SCHEMA", "table_diagnosis_to_dict", "render_table_markdown", "write_table_report"]

#: ``schema`` of a table diagnosis's ``diagnosis.json``.
TABLE_SCHEMA = "dtwin.gap.table/1"

_KEYS = (
    "module", "modules", "effect", "at", "params", "param_intervals", "fixed_combinations",
    "confidence", "bic_weight", "gap_before", "gap_refit", "gap_after", "raw_shrink_pct",
    "own_shrink_pct", "excess_shrink_pct", "free_run_rms_before", "free_run_rms_after",
    "also_needed", "notes",
)  # fmt: skip


def table_diagnosis_to_dict(d: TableDiagnosis) -> dict[str, Any]:
    """Return the JSON payload of a table diagnosis (plain types, non-finite numbers as null)."""
    payload = {"schema": TABLE_SCHEMA, **{key: getattr(d, key) for key in _KEYS}}
    payload["param_intervals"] = {k: list(v) for k, v in d.param_intervals.items()}
    payload["shrink_pct"] = d.own_shrink_pct
    payload["units"] = {name: asdict(unit) for name, unit in d.units.items()}
    payload["candidates"] = d.candidates
    payload["recording"] = {"n_samples": d.n_samples, "n_train": d.n_train,
                            "n_choose": d.n_choose, "dt": d.dt}  # fmt: skip
    return to_jsonable(payload)


def _fmt(value: Any) -> str:
    if value is None:
        return "–"
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _headline(d: TableDiagnosis) -> str:
    where = " + ".join(d.modules) if d.modules else "–"
    if d.effect == "none":
        return "No module of the twin has a gap beyond its noise floor: **none**."
    if d.effect == "unexplained":
        return f"The gap lies in **{where}**; no candidate effect explains it: **unexplained**."
    params = ", ".join(f"{k} = {_fmt(v)}" for k, v in d.params.items())
    return (
        f"The gap lies in **{where}**: **{d.effect}** at `{d.at}` ({params}); it removes "
        f"{_fmt(d.own_shrink_pct)} % of the gap a re-fitted twin leaves (scoring part), "
        f"confidence {_fmt(d.confidence)}."
    )


def render_table_markdown(d: TableDiagnosis, figure_name: str | None = "gap.png") -> str:
    """``report.md``: the answer, the units, the candidates, the intervals and the notes."""
    lines = ["# Gap diagnosis", "", _headline(d), ""]
    header = "| unit | inputs | outputs | gap | threshold | gap? | window | hold |"
    lines += ["## Units", "", header, "|---|---|---|---|---|---|---|---|"]
    for name, u in d.units.items():
        lines.append(
            f"| {name} | {', '.join(u.inputs)} | {', '.join(u.outputs)} | {u.gap_choose:.4g} | "
            f"{u.threshold:.4g} | {'yes' if u.flagged else 'no'} | {u.window} | {u.hold} |"
        )
    if d.candidates:
        lines += ["", "## Candidates (choosing part)", "", "| effect | at | gap | BIC weight |",
                  "|---|---|---|---|"]  # fmt: skip
        lines += [f"| {c['effect']} | {c['at']} | {c['gap_choose']:.4g} | {c['bic_weight']:.3f} |"
                  for c in d.candidates]  # fmt: skip
    if d.param_intervals:
        lines += ["", "## 95 % intervals", ""]
        lines += [f"- `{k}`: [{lo:.4g}, {hi:.4g}]" for k, (lo, hi) in d.param_intervals.items()]
    if d.fixed_combinations:
        lines += ["", "Combinations the data cannot separate: "]
        lines += [f"- {c}" for c in d.fixed_combinations]
    lines += ["", "## Gaps (scoring part, normalised)", ""]
    lines += [f"- before {_fmt(d.gap_before)}, re-fitted twin {_fmt(d.gap_refit)}, with the "
              f"effect {_fmt(d.gap_after)}; free run RMS {_fmt(d.free_run_rms_before)} → "
              f"{_fmt(d.free_run_rms_after)}"]  # fmt: skip
    if d.also_needed:
        lines += ["", f"Other units with a gap of their own: {', '.join(d.also_needed)}."]
    if d.notes:
        lines += ["", "## Notes", ""] + [f"- {note}" for note in d.notes]
    if figure_name:
        lines += ["", f"![gap]({figure_name})"]
    return "\n".join(lines) + "\n"


def _draw(d: TableDiagnosis, path: Path) -> None:
    """``gap.png``: the source's first output on the scoring part, recorded, twin, with effect."""
    import matplotlib.pyplot as plt

    from dtwin.figures._style import save_figure

    with plt.style.context("default"):
        fig, ax = plt.subplots(figsize=(10, 3.6))
        s = d.series
        if s:
            ax.plot(s["t"], s["recorded"], color="0.5", lw=0.8, label="recorded")
            ax.plot(s["t"], s["twin"], color="tab:blue", lw=1.2, label="twin")
            if "with_effect" in s:
                ax.plot(
                    s["t"], s["with_effect"], color="tab:red", lw=1.2, label=f"twin + {d.effect}"
                )
            ax.legend(loc="upper right", fontsize=8)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(", ".join(next(iter(d.units.values())).outputs) if not s else "output")
        ax.set_title(_headline(d).replace("**", "").replace("`", ""), fontsize=9)
        fig.tight_layout()
        save_figure(fig, [path], tight=False, dpi=100)


def write_table_report(
    d: TableDiagnosis, out_dir: str | os.PathLike, *, figure: bool = True
) -> list[Path]:
    """Write ``diagnosis.json``, ``report.md`` and (unless ``figure=False``) ``gap.png``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    json_path, md_path, png_path = out / "diagnosis.json", out / "report.md", out / "gap.png"
    write_json(table_diagnosis_to_dict(d), json_path)
    text = render_table_markdown(d, png_path.name if figure else None)
    atomic_write(md_path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    if not figure:
        return [json_path, md_path]
    _draw(d, png_path)
    return [json_path, md_path, png_path]
