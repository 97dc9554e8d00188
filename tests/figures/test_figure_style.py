"""The figure style of the set: print size, fonts, overlaps, 300-dpi PNG, one entry point.

The workflow test (tests/workflow/test_workflow.py) checks every produced artifact's files and its
``print_size_and_text`` validity check; these tests check the rules themselves, fast.
"""

from __future__ import annotations

import ast
import os
import shutil
import struct
import zlib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest
import yaml
from matplotlib import pyplot as plt
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.transforms import Bbox

from dtwin.artifacts import FigureArtifact
from dtwin.config_sections import ArxSettings
from dtwin.figures._print_check import (
    axes_and_legends_check,
    drawn_texts,
    legend_mismatches,
    print_check,
    reader_checks,
    unlabelled_axes,
)
from dtwin.figures._style import (
    COLUMN_WIDTH,
    FULL_WIDTH,
    MIN_FONT_PT,
    PNG_DPI,
    _lay_out_once,
    new_figure,
    panel_title,
    publish_artifact,
    save_figure,
    tex,
    unitless,
)
from dtwin.figures.fig01_pipeline import fig01_pipeline
from dtwin.figures.fig06_correction_distributions import bw_nrd0
from dtwin.figures.fig09_bic import (
    _figure_causes,
    _interior_caption,
    _with_interior_note,
    _with_target_note,
)
from dtwin.figures.fig10_mcda_actions import single_step_lock_ins
from dtwin.figures.fig11_sensitivity import _with_notes
from dtwin.figures.gap_benchmark import gap_benchmark
from dtwin.gapbench.scores import TARGETS, benchmark_metrics
from tests.conftest import REPO

FIGURE_MODULES = [
    *sorted((REPO / "dtwin" / "figures").glob("fig*.py")),
    REPO / "dtwin" / "figures" / "gap_benchmark.py",
]


def png_size_and_dpi(path) -> tuple[int, int, float]:
    """Width and height in pixels and the dpi of a PNG (from its IHDR and pHYs chunks)."""
    data = path.read_bytes()
    width, height = struct.unpack(">II", data[16:24])
    at = data.index(b"pHYs")
    per_metre, _, unit = struct.unpack(">IIB", data[at + 4 : at + 13])
    assert unit == 1  # metres
    assert zlib.crc32(data[at : at + 13]) == struct.unpack(">I", data[at + 13 : at + 17])[0]
    return width, height, per_metre * 0.0254


def clean_figure(width: float = FULL_WIDTH):
    figure = new_figure(2.5, width)
    ax = figure.add_subplot()
    ax.plot([0, 1], [0, 1], label="a line")
    ax.set(xlabel="time (s)", ylabel=tex("x") + " (m)")
    panel_title(ax, "A", "Short title")
    ax.legend()
    return figure


@pytest.mark.parametrize("width", [FULL_WIDTH, COLUMN_WIDTH])
def test_a_print_size_figure_with_set_fonts_passes(width):
    check = print_check(clean_figure(width))
    assert check.passed, check.observed
    assert check.observed["min_font_pt"] >= MIN_FONT_PT


def test_the_set_draws_with_matplotlibs_own_font_file_when_a_copy_is_listed_first(tmp_path):
    """A second file of DejaVu Sans (a system copy, another version) listed first in the font
    cache ties with matplotlib's own file on every property; the set's figures still use
    matplotlib's, so a PDF embeds the same font file on every machine."""
    from matplotlib import font_manager

    bundled = os.path.realpath(Path(matplotlib.get_data_path(), "fonts", "ttf", "DejaVuSans.ttf"))
    copy = tmp_path / "DejaVuSans.ttf"
    shutil.copyfile(bundled, copy)
    manager = font_manager.fontManager
    listed = manager.ttflist
    manager.ttflist = [font_manager.ttfFontProperty(font_manager.get_font(str(copy))), *listed]
    try:
        manager._findfont_cached.cache_clear()
        # without the set's style the tie goes to the copy, the first file listed
        assert os.path.realpath(font_manager.findfont("DejaVu Sans")) == os.path.realpath(copy)
        plt.close(clean_figure())
        assert os.path.realpath(font_manager.findfont("DejaVu Sans")) == bundled
    finally:
        manager.ttflist = listed
        manager._findfont_cached.cache_clear()


def test_a_wide_figure_fails():
    figure = clean_figure()
    figure.set_size_inches(12, 5)
    check = print_check(figure)
    assert not check.passed and check.observed["width_in"] == 12


def test_small_text_is_named():
    figure = clean_figure()
    figure.axes[0].text(0.1, 0.8, "tiny words", fontsize=5)
    check = print_check(figure)
    assert not check.passed and check.observed["too_small"] == ["tiny words"]


def test_overlapping_and_off_page_text_is_named():
    figure = clean_figure()
    ax = figure.axes[0]
    ax.text(0.5, 0.5, "first label")
    ax.text(0.52, 0.5, "second label")
    figure.text(0.9, 0.5, "runs off the right edge of the page")
    check = print_check(figure)
    assert not check.passed
    assert ["first label", "second label"] in check.observed["overlapping"]
    assert any("runs off" in text for text in check.observed["off_page"])


def test_hidden_text_is_not_counted():
    figure = clean_figure()
    figure.axes[0].text(0.5, 0.5, "hidden", fontsize=4, visible=False)
    assert "hidden" not in {t.text for t in drawn_texts(figure)}
    assert print_check(figure).passed


def test_a_clean_figure_passes_every_reader_check():
    checks = reader_checks(clean_figure())
    assert [c.id for c in checks] == ["print_size_and_text", "axes_and_legends"]
    assert all(c.passed for c in checks), [c.observed for c in checks]


def test_a_numeric_axis_without_label_or_unit_is_named():
    figure = clean_figure()
    ax = figure.axes[0]
    ax.set_xlabel("")
    ax.set_ylabel("position")
    assert unlabelled_axes(figure) == [
        "A Short title x: no label",
        "A Short title y: 'position' has no unit",
    ]
    ax.set_ylabel(r"$\gamma_t(k)$")  # an argument in mathtext is not a unit
    assert unlabelled_axes(figure)[1] == "A Short title y: '$\\gamma_t(k)$' has no unit"
    unitless(ax, "y")
    ax.set_xlabel("time [s]")
    assert unlabelled_axes(figure) == []


def test_categorical_hidden_and_shared_axes_need_no_own_label():
    figure = new_figure(3.0)
    top, bottom = figure.subplots(2, 1, sharex=True)
    for ax in (top, bottom):
        ax.bar(["Nominal", "Drift"], [1.0, 2.0])
        ax.set_ylabel("RMSE (m)")
    top.tick_params(labelbottom=True)  # shared with the bottom axis: its label covers both
    assert unlabelled_axes(figure) == []
    figure = new_figure(3.0)
    left, right = figure.subplots(1, 2)
    for ax in (left, right):
        ax.plot([0, 1], [0, 1])
    figure.supxlabel("time (s)")
    figure.supylabel("share of draws").set_gid("dtwin-unitless")
    assert unlabelled_axes(figure) == []


def test_a_legend_glyph_that_nothing_drawn_looks_like_is_named():
    figure = clean_figure()
    ax = figure.axes[0]
    ax.fill_between([0, 1], 0, 0.5, color="#009E73", alpha=0.3)
    handles = [
        Line2D([], [], color="C0", label="a line"),  # drawn (the clean figure's line)
        Patch(facecolor="#009E73", alpha=0.3, label="a band"),  # drawn
        Line2D([], [], color="C0", ls="--", label="dashed, never drawn"),
        Line2D([], [], color="red", marker="o", ls="none", label="red dots, never drawn"),
        Patch(facecolor="#123456", label="a patch of no drawn colour"),
    ]
    ax.legend(handles=handles)
    assert legend_mismatches(figure) == [
        "legend 'dashed, never drawn': no drawn artist looks like it",
        "legend 'red dots, never drawn': no drawn artist looks like it",
        "legend 'a patch of no drawn colour': no drawn artist looks like it",
    ]
    check = axes_and_legends_check(figure)
    assert not check.passed and check.observed["n_legend_entries"] == 5


def test_a_figure_legend_matches_artists_in_any_panel_and_repeats_are_named():
    figure = new_figure(2.5)
    left, right = figure.subplots(1, 2)
    left.plot([0, 1], [0, 1], color="C1", ls=":")
    right.scatter([0, 1], [1, 0], color="C2")
    right.errorbar([0.5], [0.5], yerr=[0.1], fmt="none", ecolor="C3")
    figure.legend(
        [
            Line2D([], [], color="C1", ls=":"),
            Line2D([], [], color="C2", marker="o", ls="none"),
            Line2D([], [], color="C3"),
            Line2D([], [], color="C2", marker="o", ls="none"),
        ],
        ["dotted", "dots", "error bars", "dots"],
        loc="outside upper center",
    )
    assert legend_mismatches(figure) == ["repeated legend label 'dots'"]


def test_png_is_300_dpi_at_print_size_and_reruns_byte_identical(tmp_path):
    paths = [tmp_path / "a.png", tmp_path / "a.pdf"]
    save_figure(clean_figure(), paths, tight=False)
    first = [p.read_bytes() for p in paths]
    save_figure(clean_figure(), paths, tight=False)
    assert [p.read_bytes() for p in paths] == first
    width, height, dpi = png_size_and_dpi(paths[0])
    assert round(dpi) == PNG_DPI
    assert (width, height) == (round(FULL_WIDTH * PNG_DPI), round(2.5 * PNG_DPI))
    assert b"/MediaBox [ 0 0 518.4 180 ]" in first[1]  # vector PDF at 7.2 x 2.5 in


def test_a_published_figure_reruns_byte_identical(tmp_path):
    paths = [tmp_path / "a.png", tmp_path / "a.pdf"]
    publish_artifact(FigureArtifact("a", clean_figure(), {}), paths, tmp_path / "a.json")
    first = [p.read_bytes() for p in paths]
    publish_artifact(FigureArtifact("a", clean_figure(), {}), paths, tmp_path / "a.json")
    assert [p.read_bytes() for p in paths] == first


def test_layout_positions_that_differ_in_their_last_bits_are_drawn_the_same():
    """The constrained layout's solver returned an axes' height 17 ulps apart in two processes
    (same inputs), and one PDF text position of fig02 rounded the other way now and then."""

    def lay_out(ulps: int) -> list[np.ndarray]:
        figure = clean_figure()
        engine = figure.get_layout_engine()
        solve = engine.execute

        def solve_off_by_ulps(fig):
            solve(fig)
            for ax in fig.axes:
                corners = ax.get_position(original=True).get_points()
                ax._set_position(Bbox(corners + ulps * np.spacing(corners)))

        engine.execute = solve_off_by_ulps
        _lay_out_once(figure)
        return [ax.get_position(original=True).get_points() for ax in figure.axes]

    exact, off = lay_out(0), lay_out(17)
    assert all(np.array_equal(a, b) for a, b in zip(exact, off, strict=True))


def test_fig01_is_drawn_at_print_size_without_collisions():
    arx = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["arx"]
    artifact = fig01_pipeline(ArxSettings.from_mapping(arx))
    check = print_check(artifact.figure)
    assert check.passed, check.observed
    assert artifact.paper_figure == "Fig. 1" and artifact.caption
    texts = {t.text for t in drawn_texts(artifact.figure)}
    assert "$y_A$" in texts and "$x$, $v$" in texts and "u_cmd" not in " ".join(texts)


def benchmark_table() -> pd.DataFrame:
    """A made-up scored table (the columns of dtwin.gapbench.scores.score_cases a figure reads)."""
    rows = []
    for effect in ("coulomb_friction", "sensor_delay", "none", "unexplained"):
        for i in range(3):
            right = not (effect == "sensor_delay" and i == 0)
            named = effect not in ("none", "unexplained")
            rows.append(
                {
                    "effect": effect,
                    "expected_effect": effect,
                    "in_list": named,
                    "magnitude": 0.1 + 0.3 * i,
                    "diagnosed_effect": effect if right else "none",
                    "confidence": (0.6, 0.85, 1.0)[i] if named and right else None,
                    "own_shrink_pct": 70.0 + 5 * i,
                    "raw_shrink_pct": 60.0 + 5 * i,
                    "excess_shrink_pct": 80.0 + 10 * i,
                    "excess_clipped": i == 2,
                    "kpi_shrink_pct": 50.0,
                    "module_ok": right,
                    "effect_ok": right,
                    "param_error": 0.01 * (i + 1) if named and right else float("nan"),
                }
            )
    return pd.DataFrame(rows)


def benchmark_metrics_of(table: pd.DataFrame) -> dict:
    """The benchmark's metrics of a made-up table (a drawing input, not a result)."""
    return benchmark_metrics(table)


def test_gap_benchmark_shares_rows_and_reads_at_print_size():
    table = benchmark_table()
    metrics = benchmark_metrics_of(table)
    artifact = gap_benchmark(table, metrics, [], TARGETS)
    check = print_check(artifact.figure)
    assert check.passed, check.observed
    matrix, shrinks, _, _errors, reliability = artifact.figure.axes
    assert matrix.get_shared_y_axes().joined(matrix, shrinks)
    rows = [label.get_text() for label in matrix.get_yticklabels()]
    own = shrinks.collections[0].get_offsets()
    # every own-share dot sits on its own effect's row of the confusion matrix
    assert {rows[int(round(y))] for _, y in own} == {"coulomb_friction", "sensor_delay"}
    assert len(shrinks.collections) == 3  # own share, raw error, excess over noise
    assert artifact.caption.startswith("12 withheld-effect cases (3 per effect)")
    assert "own share" in artifact.caption and "5/6" in artifact.caption
    # one reliability point per non-empty confidence bin: 0.6, 0.85 and 1.0
    drawn = reliability.containers[0].lines[0].get_xdata()
    assert len(drawn) == len(metrics["reliability"]) == 3


def test_bandwidth_is_r_bw_nrd0():
    values = np.array([0.0, 1.0, 2.0, 3.0, 100.0])
    # R: bw.nrd0(c(0, 1, 2, 3, 100)) = 0.9 * min(sd, IQR / 1.34) * 5^(-1/5)
    assert bw_nrd0(values) == pytest.approx(0.9 * (2.0 / 1.34) * 5 ** (-0.2))
    heavy = np.r_[np.random.default_rng(0).normal(0, 0.003, 900), np.linspace(-0.1, 0.1, 100)]
    scott = np.std(heavy, ddof=1) * len(heavy) ** (-0.2)
    assert bw_nrd0(heavy) < 0.5 * scott  # follows the core, not the tails


def test_a_single_raw_step_that_locks_an_action_in_is_counted():
    best = ["NoAction"] * 3 + ["BiasCorrect"] + ["ReidentifyPlant"] * 6
    action = ["NoAction"] * 3 + ["BiasCorrect"] * 4 + ["ReidentifyPlant"] * 3
    timeline = pd.DataFrame({"best": best, "action": action, "regime": ["DynamicsOff"] * 10})
    assert single_step_lock_ins(timeline) == {
        "n": 1,
        "steps_held": 3,
        "steps_held_by_regime": {"DynamicsOff": 3},
    }


@pytest.mark.parametrize("path", FIGURE_MODULES, ids=lambda p: p.stem)
def test_every_figure_starts_from_the_shared_style(path):
    """Figures are created only through new_figure (print size, fonts); no suptitle."""
    tree = ast.parse(path.read_text())
    calls = {
        node.func.attr
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
    }
    names = {
        node.func.id
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    }
    assert "new_figure" in names
    assert not calls & {"suptitle", "tight_layout", "set_size_inches"}
    assert "figsize" not in path.read_text()


def test_gap_benchmark_draws_the_paper_family_only():
    table = benchmark_table().assign(family="paper")
    rig = table.head(2).assign(family="rig", expected_effect="rig_only_effect")
    metrics = benchmark_metrics_of(table)
    artifact = gap_benchmark(pd.concat([table, rig]), metrics, [], TARGETS)
    rows = [label.get_text() for label in artifact.figure.axes[0].get_yticklabels()]
    assert "rig_only_effect" not in rows
    assert artifact.caption.endswith("2 cases of other families are in the JSON only.")


def test_gap_benchmark_draws_each_arm_and_the_rig_family_in_panel_f():
    """The arms and the rig family are rows of the figure, not only JSON."""
    from dtwin.gapbench.scores import benchmark_metrics

    paper = benchmark_table().assign(family="paper", arm="default")
    noisy = benchmark_table().assign(family="paper", arm="noisy_x")
    rig = benchmark_table().head(4).assign(family="rig", arm="rig")
    table = pd.concat([paper, noisy, rig], ignore_index=True)
    metrics = benchmark_metrics(table)
    artifact = gap_benchmark(table, metrics, [], TARGETS)
    assert len(artifact.figure.axes) == 6
    arms = artifact.figure.axes[5]
    labels = [label.get_text() for label in arms.get_yticklabels()]
    assert labels == ["default (12)", "(c) noisy x, no v, z (12)", "rig family (4)"]
    check = print_check(artifact.figure)
    assert check.passed, check.observed
    assert artifact.caption.endswith("4 cases of other families are in panel F and the JSON.")


def test_a_bic_minimum_inside_the_sweep_away_from_k8_gets_its_cause():
    from dtwin.artifacts import Check

    claim = Check(
        id="bic_minimum_at_k8_nominal_residuals",
        kind="claim",
        statement="paper: minimum at K = 8",
        expected=8,
        observed=11,
        passed=False,
    )
    stable = {"nominal_residuals": {"max_gain": 0.2, "at_k": 12}}
    noted = _with_interior_note(claim, {"nominal_residuals": 8}, stable)
    assert noted.note.startswith("minimum at K = 11 inside the sweep, on our draw; R's K = 8")
    assert "moves no best fit" in noted.note
    assert _figure_causes([noted]) == {"nominal_residuals": "min K=11, not 8: our draw"}
    assert _interior_caption([noted]).startswith("Minimum at K = 11 (nominal residuals)")
    unstable = {"nominal_residuals": {"max_gain": 14.0, "at_k": 12}}
    noted = _with_interior_note(claim, {"nominal_residuals": 8}, unstable)
    assert "still gains 14.0 log-likelihood at K = 12" in noted.note
    assert _figure_causes([noted])["nominal_residuals"].endswith("draw or optimiser")


def test_the_sweeps_failed_targets_and_fig11_balanced_claim_get_causes():
    from dtwin.artifacts import Check

    def failed(check_id, observed, kind="claim"):
        return Check(check_id, kind, "s", None, observed, False)

    from dtwin.config_sections import BicSettings

    bic = BicSettings(ks=(2, 3), n_restarts=4, k_max=16)
    bracket = failed("bic_minimum_bracketed", {"fault_features": {"k_min": 15, "k_last": 16}})
    assert _with_target_note(bracket, bic).note.startswith(
        "sweep range: the minimum (fault features K = 15) sits at the last two K fitted"
    )
    gains = {"a": {"max_gain": 3.0, "at_k": 5}, "b": {"max_gain": 836.0, "at_k": 2}}
    stable = _with_target_note(failed("best_loglik_stable_in_starts", gains), bic)
    assert "still gains 836.0 log-likelihood (b, K = 2)" in stable.note
    balanced = failed(
        "balanced_noise_mid_to_high_20s", {"ours": 36.4, "r_signals": 39.7, "r_rerun": 24.9}
    )
    (noted,) = _with_notes([balanced], "ours 36 %", n_restarts=10)
    partial = failed("balanced_noise_mid_to_high_20s", {"ours": 36.4, "r_rerun": None})
    assert "ours 36.4 %; with 10" in _with_notes([partial], "m", n_restarts=10)[0].note
    assert noted.note.startswith(
        "optimiser: medians over m_A = m_B ours 36.4 %, our HMM on R's exact signals 39.7 %, "
        "R's re-run 24.9 %; with 10 EM starts"
    )


def test_panel_f_names_every_arm_of_the_gap_layer():
    """The figures layer may not import dtwin.gap, so panel F keeps its own arm labels: they
    must cover every arm of dtwin/gapbench/arms.py, the default arm and the rig family."""
    from dtwin.figures.gap_benchmark import _GROUP_LABELS
    from dtwin.gapbench.arms import ARMS, DEFAULT_ARM

    assert set(_GROUP_LABELS) == {DEFAULT_ARM, *ARMS, "rig"}
    assert list(_GROUP_LABELS)[1 : 1 + len(ARMS)] == list(ARMS)


def test_a_moved_minimum_that_moves_on_r_signals_too_blames_the_optimiser():
    from dtwin.artifacts import Check
    from dtwin.figures.fig09_bic import _on_r_signals

    claim = Check(
        id="bic_minimum_at_k8_fault_features",
        kind="claim",
        statement="paper: minimum at K = 8",
        expected=8,
        observed=15,
        passed=False,
    )
    ks = np.arange(2, 19)
    r_signals = pd.DataFrame(
        {"dataset": "fault_features", "K": ks, "log_likelihood": 10.0 * ks, "bic": (ks - 16.0) ** 2}
    )
    r_tables = {"fault_features": pd.DataFrame({"K": [8, 9], "log_likelihood": [91.7, 219.1]})}
    on_r = _on_r_signals(r_signals, r_tables)
    assert {k: v for k, v in on_r["fault_features"].items() if k != "sweep"} == {
        "k_star": 16,
        "log_likelihood_k8": 80.0,
        "r_log_likelihood_k8": 91.7,
        "r_starts": "5 EM starts per K <= 9",
    }
    noted = _with_interior_note(claim, {"fault_features": 8}, {}, on_r)
    assert "Cause: optimiser (this sweep on R's own seed-11 signals gives K* = 16, not 8" in (
        noted.note
    )
    assert _figure_causes([noted]) == {
        "fault_features": "min K=15, not 8: optimiser (see R's signals)"
    }
    same = {"fault_features": {**on_r["fault_features"], "k_star": 8}}
    assert "Cause: draw (" in _with_interior_note(claim, {"fault_features": 8}, {}, same).note
