"""The output folder of ``dtwin regimes``: the model, the posteriors, the correction, a report.

Specification: docs/monitor.md §dtwin regimes. :func:`write_regimes_report` writes into a
folder (the command line wraps it in :func:`dtwin.artifacts.atomic_write_folder`):

- ``regimes.json``: the fitted model, everything ``dtwin monitor`` needs
  (:func:`dtwin.monitor.model_file.regimes_file_mapping`);
- ``posteriors.csv``: ``t``, ``settling`` (1 inside the settling period), the filtered
  ``regime`` and ``nominal``, ``smoothed_S1 … smoothed_SK`` (the paper's, which look ahead),
  ``filtered_S1 … filtered_SK, filtered_unknown`` (what the monitor gives), and ``action``
  with an actions table; posteriors empty inside the settling period;
- ``corrected.csv``: ``t`` and per channel ``<channel>`` (recorded), ``<channel>|twin``,
  ``<channel>|smoothed`` and ``<channel>|filtered`` (the twin corrected with smoothed and with
  filtered posteriors);
- ``report.md`` and ``regimes.png`` (residuals, regime timeline, posteriors, raw and corrected).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from dtwin.artifacts import atomic_write, write_csv, write_json
from dtwin.monitor.batch_regimes import RegimesResult
from dtwin.monitor.model_file import regimes_file_mapping

__all__ = ["posteriors_table", "corrected_table", "render_markdown", "write_regimes_report"]


def _padded(values: np.ndarray, n: int) -> np.ndarray:
    """``values`` (m, ...) after ``n − m`` rows of NaN."""
    out = np.full((n, *values.shape[1:]), np.nan)
    out[n - len(values) :] = values
    return out


def posteriors_table(result: RegimesResult) -> pd.DataFrame:
    """Return ``posteriors.csv`` (module docstring), one row per sample."""
    n, s = len(result.t), result.settling
    model, tracked = result.regime_fit.model, result.tracked
    labels = list(model.labels)
    regime = np.array(["settling"] * n, dtype=object)
    regime[s:] = np.array(labels)[tracked.regime]
    table = pd.DataFrame({"t": result.t, "settling": (np.arange(n) < s).astype(int)})
    table["regime"] = regime
    table["nominal"] = _padded(tracked.nominal.astype(float), n)
    table["novelty"] = _padded(tracked.novelty, n)
    smoothed = _padded(result.regime_fit.fit.smoothed, n)
    for j, label in enumerate(labels[:-1]):
        table[f"smoothed_{label}"] = smoothed[:, j]
    filtered = _padded(tracked.posteriors, n)
    for j, label in enumerate(labels):
        table[f"filtered_{label}"] = filtered[:, j]
    if tracked.action is not None:
        action = np.array([""] * n, dtype=object)
        action[s:] = np.array(result.actions.alternatives)[tracked.action]
        table["action"] = action
    return table


def corrected_table(result: RegimesResult) -> pd.DataFrame:
    """Return ``corrected.csv`` (module docstring), one row per sample."""
    n = len(result.t)
    table = pd.DataFrame({"t": result.t})
    smoothed, filtered = result.simulated.copy(), result.simulated.copy()
    smoothed[:, result.kept] += _padded(result.smoothed_applied, n)
    filtered[:, result.kept] = _padded(result.tracked.corrected, n)
    for c, channel in enumerate(result.channels):
        table[channel] = result.recorded[:, c]
        table[f"{channel}|twin"] = result.simulated[:, c]
        table[f"{channel}|smoothed"] = smoothed[:, c]
        table[f"{channel}|filtered"] = filtered[:, c]
    return table


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(values**2)))


def render_markdown(result: RegimesResult, figure: str | None) -> str:
    """Return ``report.md``: the twin, the regimes, the correction, the false alarms."""
    fit, model = result.regime_fit, result.regime_fit.model
    s = result.settling
    lines = [
        "# dtwin regimes",
        "",
        f"{len(result.t)} samples, dt = {result.dt:g} s; residual channels "
        f"{', '.join(f'`{c}`' for c in result.channels)}. Settling period {s} samples "
        f"({s * result.dt:g} s). Nominal stretch samples {result.rows[0]} … {result.rows[1] - 1}.",
        "",
        f"**K = {model.n_states}** regimes ({'BIC minimum' if fit.bic is not None else 'given'}),"
        " plus `unknown`.",
        "",
        "| regime | nominal | occupancy (filtered) | mean residual (channel units) | action |",
        "|---|---|---|---|---|",
    ]
    occupancy = result.tracked.posteriors.mean(axis=0)
    means = np.vstack([model.state_means, np.full(len(model.channels), np.nan)])
    for j, label in enumerate(model.labels):
        nominal = "yes" if model.nominal_mask[j] else "no"
        mean = ", ".join(f"{v:.4g}" for v in means[j]) if j < model.n_states else "–"
        action = result.per_regime.get(label, "–")
        lines.append(f"| {label} | {nominal} | {occupancy[j]:.3f} | {mean} | {action} |")
    residual = result.residuals[s:, result.kept]
    after = result.recorded[s:, result.kept] - result.tracked.corrected
    lines += ["", "Residual RMS before and after the filtered correction (causal):", ""]
    for c, channel in enumerate(model.channels):
        lines.append(f"- `{channel}`: {_rms(residual[:, c]):.4g} → {_rms(after[:, c]):.4g}")
    if result.dropped:
        dropped = ", ".join(f"`{c}`" for c in result.dropped)
        lines += ["", f"Left out (residual zero to round-off: the recording satisfies the module "
                  f"exactly): {dropped}."]  # fmt: skip
    alarms = result.false_alarms
    stretch, simulated = alarms["nominal_stretch"], alarms["simulated_unknown"]
    lines += [
        "",
        f"False alarms (hold {alarms['hold']} samples): {stretch['events']} events on the "
        f"nominal stretch ({stretch['hours']:.3g} h; ≤ {stretch['upper95_per_hour']:.3g}/h at "
        f"95 %); {simulated['events']} into `unknown` on {simulated['hours']:.3g} h simulated "
        f"from the fitted regimes (≤ {simulated['upper95_per_hour']:.3g}/h at 95 %).",
    ]
    bound = alarms.get("novelty_bound")
    if bound is not None:
        lines[-1] += (
            f" The novelty test alarms at {bound['threshold_nats']:.3g} nats: at most once per "
            f"{bound['samples']:.3g} samples ({bound['per_hour']:.3g}/h) on residuals that "
            "follow the model."
        )
    if figure:
        lines += ["", f"![regimes]({figure})"]
    return "\n".join(lines) + "\n"


def _draw(result: RegimesResult, path: Path) -> None:
    """``regimes.png``: residuals, regime timeline, filtered posteriors, raw and corrected."""
    import matplotlib.pyplot as plt

    from dtwin.figures._style import STATE_COLORS, save_figure

    s, t = result.settling, result.t
    model, tracked = result.regime_fit.model, result.tracked
    colors = [STATE_COLORS[j % len(STATE_COLORS)] for j in range(model.n_states)] + ["#b3001b"]
    with plt.style.context("default"):
        fig, axes = plt.subplots(4, 1, figsize=(10, 8), sharex=True)
        z = (result.residuals[s:, result.kept] - model.center) / model.scale
        for c, channel in enumerate(model.channels):
            axes[0].plot(t[s:], z[:, c], lw=0.6, label=channel)
        axes[0].set_ylabel("residual (z)")
        axes[0].legend(loc="upper right", fontsize=7)
        axes[1].scatter(t[s:], tracked.regime, c=[colors[r] for r in tracked.regime], s=2)
        axes[1].set_yticks(range(len(model.labels)), model.labels, fontsize=7)
        axes[1].set_ylabel("regime")
        axes[2].stackplot(t[s:], tracked.posteriors.T, colors=colors, labels=model.labels)
        axes[2].set_ylabel("filtered P")
        axes[2].legend(loc="upper right", fontsize=7, ncol=min(len(colors), 6))
        first = result.kept[0]
        axes[3].plot(t, result.recorded[:, first], color="0.5", lw=0.7, label="recorded")
        axes[3].plot(t, result.simulated[:, first], color="tab:blue", lw=0.9, label="twin")
        axes[3].plot(t[s:], tracked.corrected[:, 0], color="tab:red", lw=0.9,
                     label="twin corrected (filtered)")  # fmt: skip
        axes[3].set_ylabel(model.channels[0])
        axes[3].set_xlabel("time (s)")
        axes[3].legend(loc="upper right", fontsize=7)
        fig.tight_layout()
        save_figure(fig, [path], tight=False, dpi=100)
        plt.close(fig)


def write_regimes_report(
    result: RegimesResult, out_dir: str | os.PathLike, *, figure: bool = True
) -> list[Path]:
    """Write the folder's five files (module docstring); return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        out / name for name in ("regimes.json", "posteriors.csv", "corrected.csv", "report.md")
    ]
    write_json(regimes_file_mapping(result), paths[0])
    write_csv(posteriors_table(result), paths[1])
    write_csv(corrected_table(result), paths[2])
    text = render_markdown(result, "regimes.png" if figure else None)
    atomic_write(paths[3], lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    if figure:
        paths.append(out / "regimes.png")
        _draw(result, paths[-1])
    return paths
