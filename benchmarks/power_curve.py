"""Detection power per effect (docs/gap.md §Detection power): rows to a CSV, resumable.

    python benchmarks/power_curve.py OUT.csv [--per-level 20] [--n-samples 1500] [--seed 39000]
    python benchmarks/power_curve.py OUT.csv --summary [--plot FIGURE.png]

For every catalogue effect of the default arm and each of :data:`LEVELS` (the generator's
magnitude), ``--per-level`` recordings of ``--n-samples`` samples are generated and diagnosed
with config/config.yaml's ``gap.diagnose`` settings; clean recordings of every conditions arm
(:data:`CLEAN`, ``--clean`` each) give the false-alarm rate. Recordings are made round robin
(number, then case type, then level), so a run stopped early has a like share of every type.
Rows already in OUT.csv are kept (a rerun continues). Seed of a row:
``seed + 1000·(type index) + 50·(level index) + number``, the type's index in the full
list (the catalogue's effects, then :data:`CLEAN`), the level's in :data:`LEVELS`. One process:
run it under ``nice``.
``--summary`` prints the tables of docs/gap.md §Detection power from OUT.csv (and draws the
curves with ``--plot``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from dtwin.gapbench.generator import IN_LIST_EFFECTS, MIN_MAGNITUDE  # noqa: E402
from dtwin.gapbench.power import (  # noqa: E402
    INVALID,
    POWER_COLUMNS,
    detection_limits,
    power_row,
    power_table,
)
from dtwin.proportions import wilson_interval  # noqa: E402

#: The magnitudes of the ladder: the generator's 0 is its faintest random case ("barely above
#: the noise"), 1 strong; below 0 its maps are extrapolated down to invisible (MIN_MAGNITUDE).
LEVELS = tuple(float(v) for v in np.linspace(MIN_MAGNITUDE, 1.0, 9))
#: Clean case types: the default arm's and every arm that changes the conditions
#: (dtwin/gapbench/arms.py), so false alarms are read under the same conditions.
CLEAN = (
    "none",
    "no_noise__none",
    "wrong_noise__none",
    "noisy_x__none",
    "continuous__none",
    "harder__none",
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--per-level", type=int, default=20)
    parser.add_argument("--n-samples", type=int, default=1500)
    parser.add_argument("--seed", type=int, default=39000)
    parser.add_argument("--effects", nargs="*", default=list(IN_LIST_EFFECTS))
    parser.add_argument("--clean", type=int, default=40)
    parser.add_argument(
        "--set", nargs="*", default=[], metavar="KEY=VALUE", help="gap.diagnose overrides"
    )
    parser.add_argument("--levels", nargs="*", type=float, default=list(LEVELS))
    parser.add_argument("--summary", action="store_true")
    parser.add_argument("--plot", type=Path, default=None)
    args = parser.parse_args()
    if args.summary:
        summarise(pd.read_csv(args.out), args.plot)
        return
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    settings = dict(config["gap"]["diagnose"])
    settings.update({k: float(v) for k, v in (item.split("=") for item in args.set)})
    done = set()
    if args.out.exists():
        old = pd.read_csv(args.out)
        done = set(zip(old["effect"], old["seed"].astype(int), strict=True))
    else:
        args.out.write_text(",".join(POWER_COLUMNS) + "\n")
    types = [*args.effects, *CLEAN]
    canonical = [*IN_LIST_EFFECTS, *CLEAN]  # a type's seeds do not depend on the others chosen
    for number in range(max(args.per_level, args.clean)):
        for effect in types:
            index = canonical.index(effect)
            clean = effect in CLEAN
            if number >= (args.clean if clean else args.per_level):
                continue
            for place, level in enumerate([None] if clean else LEVELS):
                if not clean and level not in args.levels:
                    continue
                seed = args.seed + 1000 * index + 50 * place + number
                if (effect, seed) in done:
                    continue
                row = power_row(
                    effect,
                    level,
                    seed,
                    nominal=config["twin"],
                    diagnose_settings=settings,
                    n_samples=args.n_samples,
                )
                with args.out.open("a") as handle:
                    handle.write(",".join(str(row[c]) for c in POWER_COLUMNS) + "\n")


def _share(k: int, n: int) -> str:
    low, high = wilson_interval(k, n)
    return f"{k}/{n} = {k / n:.2f} [{low:.2f}–{high:.2f}]"


def summarise(rows: pd.DataFrame, plot: Path | None) -> None:
    """Print the detection limits, the shares per level and the false alarms (markdown)."""
    rows = rows[rows["answer"] != INVALID]
    clean = rows["effect"].isin(CLEAN)
    limits = detection_limits(rows.to_dict("records")).set_index("effect")
    table = power_table(rows[~clean].to_dict("records"))
    print(
        "| effect | n | SNR named in 50 % | 90 % | share named per magnitude "
        + " ".join(f"{v:g}" for v in LEVELS)
        + " |"
    )
    print("|---|---|---|---|---|")
    for effect, group in table.groupby("effect"):
        shares = " ".join(f"{s:.2f}" for s in group.sort_values("level")["share"])
        row = limits.loc[effect]
        print(
            f"| {effect} | {int(row['n'])} | {row['snr_50']:.2g} | {row['snr_90']:.2g} | {shares} |"
        )
    print("\n| clean recordings | `none` |\n|---|---|")
    for effect in CLEAN:
        group = rows[rows["effect"] == effect]
        if len(group):
            print(f"| {effect} | {_share(int(group['named'].sum()), len(group))} |")
    print(
        "\n| threshold × f | clean `none` (all arms) | faint effects located (magnitude −1 to 0) |"
    )
    print("|---|---|---|")
    faint = rows[~clean & rows["level"].between(-1.0, 0.0)]
    for factor in (0.8, 0.85, 0.9, 0.95, 1.0):
        quiet = int((rows[clean]["max_ratio"] <= factor).sum())
        seen = int((faint["gap_ratio"] > factor).sum())
        print(f"| {factor:g} | {_share(quiet, int(clean.sum()))} | {_share(seen, len(faint))} |")
    if plot is not None:
        _plot(rows[~clean], rows[clean], plot)


def _plot(effects: pd.DataFrame, clean: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, ax = plt.subplots(figsize=(7.0, 4.2), constrained_layout=True)
    bins = np.logspace(-2, 2.5, 19)
    centres = np.sqrt(bins[1:] * bins[:-1])
    for number, (effect, group) in enumerate(effects.groupby("effect")):
        index = np.digitize(group["snr"], bins) - 1
        shares = [
            group["named"][index == i].mean() if (index == i).sum() >= 5 else np.nan
            for i in range(len(centres))
        ]
        style = "-" if number < 10 else "--"  # ten colours in the cycle
        ax.plot(centres, shares, style, marker=".", lw=1, label=effect.replace("_", " "))
    ax.axhline(1 - clean["named"].mean(), color="k", ls=":", lw=1, label="clean: false alarms")
    ax.set(
        xscale="log",
        xlabel="effect's RMS over its module's noise floor (SNR)",
        ylabel="share named",
        ylim=(-0.02, 1.02),
    )
    ax.legend(fontsize=6, ncol=2)
    figure.savefig(path, dpi=150)


if __name__ == "__main__":
    main()
