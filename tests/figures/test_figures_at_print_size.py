"""What a reader relies on, for every figure, drawn fast from small synthetic inputs.

Each figure's own drawing function (``plot_*``, or the artifact function where it needs no
pipeline table) is fed a small table with the columns the pipeline writes, then held to the
reader checks the pipeline itself applies (:func:`dtwin.figures._print_check.reader_checks`):
print width and height, no text under 7 pt, no text over text or off the page, every numeric
axis labelled with its unit (or declared unitless), every legend entry drawn. The workflow test
(tests/workflow/test_workflow.py, slow) asserts the same checks on the pipeline's own figures
through each artifact's JSON. The inputs are random but seeded; the values are not results.
"""

from __future__ import annotations

import functools

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
import yaml
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine

from dtwin.artifacts import FigureArtifact, to_jsonable
from dtwin.config_sections import ArxSettings
from dtwin.fault_injection import FEATURES
from dtwin.figures._correction_cause import unchanged_cause
from dtwin.figures._print_check import reader_checks
from dtwin.figures._style import PNG_DPI, publish_artifact, save_figure
from dtwin.figures.fig01_pipeline import fig01_pipeline
from dtwin.figures.fig02_arx_vs_physics import plot_arx_vs_physics
from dtwin.figures.fig03_residual_acf import plot_residual_acf
from dtwin.figures.fig04_hmm_posteriors import plot_hmm_posteriors
from dtwin.figures.fig05_correction_timeseries import plot_correction_timeseries
from dtwin.figures.fig06_correction_distributions import plot_correction_distributions
from dtwin.figures.fig07_fault_posteriors import plot_fault_posteriors
from dtwin.figures.fig08_feature_separability import plot_feature_separability
from dtwin.figures.fig09_bic import plot_bic
from dtwin.figures.fig10_mcda_actions import plot_mcda_actions
from dtwin.figures.fig11_sensitivity import plot_sensitivity
from dtwin.figures.fig12_claims_across_draws import plot_claims_across_draws
from dtwin.figures.fig13_ar_hmm import plot_ar_hmm
from dtwin.figures.gap_benchmark import gap_benchmark
from dtwin.twin.wiring import MODULES
from tests.conftest import REPO
from tests.figures.test_figure_style import benchmark_metrics_of, benchmark_table

DT = 0.05
T = np.arange(400) * DT
REGIMES = ("Nominal", "SensorNoisy", "DynamicsOff", "Drift")
SCHEDULE = np.select(
    [T < 5.0, T < 10.0, T < 14.5], ["Nominal", "SensorNoisy", "DynamicsOff"], "Drift"
)
RESIDUALS = [m.residual for m in MODULES]


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


def smooth(n_columns: int, scale: float = 1.0, seed: int = 0) -> np.ndarray:
    """``(400, n_columns)`` random walks (a pipeline signal's look), one spike at 10 s."""
    walk = np.cumsum(rng(seed).normal(0, scale * 0.05, (len(T), n_columns)), axis=0)
    walk[200] += 20 * scale
    return walk


def draw_fig01():
    arx = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["arx"]
    return fig01_pipeline(ArxSettings.from_mapping(arx)).figure


def draw_fig02():
    signals = ["u_cmd", "u_act", "x", "v", "y_A", "y_B", "y_fused", "z"]
    physics = pd.DataFrame(smooth(len(signals)), columns=signals).assign(t=T)
    surrogate = physics.assign(**{s: physics[s] * 1.02 for s in signals})
    return plot_arx_vs_physics(physics, surrogate, MODULES, t_train_end=10.0)


def draw_fig03():
    lags = np.arange(41)
    residuals = pd.DataFrame(smooth(len(RESIDUALS), 0.01), columns=RESIDUALS).assign(t=T)
    acf = pd.DataFrame({e: 0.98**lags for e in RESIDUALS}).assign(lag=lags)
    white = pd.DataFrame({"lag": lags, "white": np.r_[1.0, rng().normal(0, 0.05, 40)]})
    return plot_residual_acf(rng().normal(size=400), white, residuals, acf, RESIDUALS, 0.098)


def draw_fig04():
    k = 4
    gamma = rng().dirichlet(np.full(k, 0.1), len(T))
    states = pd.DataFrame(
        {"t": T, "state": gamma.argmax(1) + 1}
        | {f"gamma_S{i + 1}": gamma[:, i] for i in range(k)}
        | {f"filtered_S{i + 1}": np.roll(gamma[:, i], 3) for i in range(k)}
    )
    features = ["e0", "e1", "e2a", "e2b", "e3", "e4"]
    summary = {
        "states": [f"S{i + 1}" for i in range(k)],
        "features": features,
        "means_z": rng().normal(0, 1.5, (k, len(features))).tolist(),
        "transmat": (np.full((k, k), 0.01) + np.eye(k) * 0.96).tolist(),
        "log_likelihood": -6312.3,
    }
    return plot_hmm_posteriors(states, summary)


def correction_residuals() -> pd.DataFrame:
    before = smooth(len(RESIDUALS), 0.02, seed=1)
    columns = {f"{e}_before": before[:, i] for i, e in enumerate(RESIDUALS)}
    columns |= {f"{e}_smoothed": 0.7 * before[:, i] for i, e in enumerate(RESIDUALS)}
    return pd.DataFrame({"t": T, "regime": SCHEDULE} | columns)


def causes() -> dict[str, str]:
    stats = {"mean": -0.0006, "rms": 0.064}
    return {e: unchanged_cause(e, 0.03, 22.9, stats) for e in ("e1", "e4")}


def draw_fig05():
    metrics = pd.DataFrame(
        [
            {"variant": v, "channel": e, "drmse_pct": 30.0}
            for v in ("smoothed", "filtered")
            for e in RESIDUALS
        ]
    )
    return plot_correction_timeseries(correction_residuals(), metrics, causes())


def draw_fig06():
    return plot_correction_distributions(correction_residuals(), causes())


def draw_fig07():
    gamma = rng().dirichlet(np.full(4, 0.2), len(T))
    posteriors = pd.DataFrame(
        {"t": T, "regime": SCHEDULE, "mapped_regime": np.roll(SCHEDULE, 5)}
        | {f"p_{r}": gamma[:, i] for i, r in enumerate(REGIMES)}
    )
    confusion = {p: {a: float(90 if p == a else 5) for a in REGIMES} for p in REGIMES}
    restarts = [{"log_likelihood": -2300.0 + 40 * i, "accuracy": 0.6 + 0.02 * i} for i in range(10)]
    scores = {"accuracy": 0.837, "macro_f1": 0.837, "kappa": 0.782}
    scenario = scores | {"confusion": confusion, "restarts": restarts}
    r_scores = {"accuracy": 0.850, "macro_f1": 0.85, "kappa": 0.8}
    return plot_fault_posteriors(posteriors, scenario, r_scores)


def draw_fig08():
    values = rng().normal(size=(len(T), len(FEATURES)))
    values[200, :] = -20.6  # a derivative spike beyond the clip
    return plot_feature_separability(pd.DataFrame(values, columns=FEATURES), SCHEDULE)


def draw_fig09():
    ks = np.arange(1, 10)
    table = pd.concat(
        [
            pd.DataFrame({"dataset": name, "K": ks, "bic": 15000 - 2000 * np.log(ks) + 30 * ks})
            for name in ("nominal_residuals", "fault_features")
        ]
    )
    r_tables = {
        name: pd.DataFrame({"K": ks, "bic": 15500 - 2100 * np.log(ks) + 60 * ks})
        for name in ("nominal_residuals", "fault_features")
    }
    causes = {"nominal_residuals": "min K=11, not 8: our draw"}  # the longest cause line
    return plot_bic(table, r_tables, n_restarts=10, causes=causes)


def draw_fig10():
    from dtwin.figures.fig10_mcda_actions import ACTION_ORDER

    actions = np.asarray(ACTION_ORDER)[np.arange(len(T)) // 70 % len(ACTION_ORDER)]
    timeline = pd.DataFrame(
        {
            "t": T,
            "regime": SCHEDULE,
            "action": actions,
            "best": np.roll(actions, 3),
            "confidence": rng().uniform(0, 0.3, len(T)),
            "gate": False,
        }
    )
    return plot_mcda_actions(timeline, warm_up_s=0.98)


def draw_fig11(n_replicates: int = 1):
    """Fig. 11; with several replicates it draws interval bars and their legend entry."""
    spread = 2.0 if n_replicates > 1 else 0.0
    rows = []
    for m_a in (0.5, 1.0, 1.5):
        for m_b in (0.5, 1.0, 1.5):
            for alpha in (0.2, 0.4, 0.6, 0.8):
                for source, method in (("ours", "code"), ("ours", "paper"), ("r_signals", "code")):
                    value = 16.0 if (m_a, m_b) == (0.5, 1.5) and method == "code" else 36.5
                    rows.append(
                        {
                            "m_A": m_a,
                            "m_B": m_b,
                            "alpha": alpha,
                            "source": source,
                            "method": method,
                            "n_replicates": n_replicates,
                            "drmse_e1_mean": value,
                            "drmse_e1_lo": value - spread,
                            "drmse_e1_hi": value + spread,
                        }
                    )
    summary = pd.DataFrame(rows)
    r_sweep = summary[summary["source"] == "ours"].assign(drmse_e1_pct=30.0)
    return plot_sensitivity(summary, r_sweep, ["code", "paper"], interval=0.9)


def draw_fig12():
    names = ["fig05_correction_timeseries:lowered_in_m1", "fig09_bic:min_at_k8"]
    claims = pd.DataFrame(
        {
            "claim": names,
            "share": [0.3, 0.6],
            "low": [0.2, 0.5],
            "high": [0.4, 0.7],
            "draw0": [False, True],
            "n": 20,
        }
    )
    table = pd.DataFrame(
        {
            "dynamics_off_mean_x": rng().normal(0, 0.1, 20),
            "drmse_pct_e1": rng().uniform(0, 30, 20),
            "drmse_pct_e4": rng().uniform(0, 30, 20),
        }
    )
    r_values = {"dynamics_off_mean_x": -0.209, "drmse_pct_e1": 22.9, "drmse_pct_e4": 23.0}
    k_star = {
        name: {"n": 10, "n_starts": 4, "counts": counts, "main_run": main, "paper": 8}
        for name, counts, main in (
            ("nominal_residuals", {"11": 3, "12": 5, "14": 2}, 14),
            ("fault_features", {"13": 4, "15": 6}, 15),
        )
    }
    return plot_claims_across_draws(claims, table, r_values, k_star)


def draw_fig13():
    k = np.arange(1, 9)
    ar_table = pd.DataFrame(
        {"K": k, "bic": 5000 - 300 * k + 40 * k**2, "accuracy": rng().uniform(0.3, 0.8, 8)}
    )
    gaussian_table = pd.DataFrame({"K": k, "bic": 6000 - 200 * k + 15 * k**2})
    return plot_ar_hmm(ar_table, gaussian_table, 0.84)


def draw_gap_benchmark():
    table = benchmark_table()
    metrics = benchmark_metrics_of(table)
    return gap_benchmark(table, metrics, [], {"median_own_shrink_pct": 70.0}).figure


FIGURES = {
    "fig01_pipeline": draw_fig01,
    "fig02_arx_vs_physics": draw_fig02,
    "fig03_residual_acf": draw_fig03,
    "fig04_hmm_posteriors": draw_fig04,
    "fig05_correction_timeseries": draw_fig05,
    "fig06_correction_distributions": draw_fig06,
    "fig07_fault_posteriors": draw_fig07,
    "fig08_feature_separability": draw_fig08,
    "fig09_bic": draw_fig09,
    "fig10_mcda_actions": draw_fig10,
    "fig11_sensitivity": draw_fig11,
    "fig11_sensitivity_3_replicates": lambda: draw_fig11(n_replicates=3),
    "fig12_claims_across_draws": draw_fig12,
    "fig13_ar_hmm": draw_fig13,
    "gap_benchmark": draw_gap_benchmark,
}


def test_every_published_figure_has_a_fast_reader_test():
    """A new artifact in workflow/artifacts.yaml needs its drawing here too."""
    artifacts = yaml.safe_load((REPO / "workflow" / "artifacts.yaml").read_text())
    published = {name for names in artifacts.values() for name in names}
    assert published <= set(FIGURES), sorted(published - set(FIGURES))


@functools.cache
def checks_of(name: str) -> tuple:
    """The reader checks of a fresh draw of ``FIGURES[name]``, drawn once per test process:
    the reader test and the publishing test (which runs after it, in this file) both read them."""
    figure = FIGURES[name]()
    checks = tuple(reader_checks(figure))
    plt.close(figure)
    return checks


@pytest.mark.parametrize("name", sorted(FIGURES))
def test_figure_passes_the_reader_checks(name):
    for check in checks_of(name):
        assert check.passed, (check.id, check.observed)


@pytest.mark.parametrize("name", ["fig09_bic", "gap_benchmark"])
def test_publishing_lays_out_once_and_draws_the_pdf_where_the_png_is(tmp_path, monkeypatch, name):
    """publish_artifact lays the figure out once, at 300 dpi; the PNG and the PDF share it.

    The PNG is the one ``savefig`` writes at 300 dpi with its own constrained layout (the same
    bytes), and its reader checks find what a separate check draw (at the figure's dpi) finds.
    The PDF is drawn from the PNG's layout: ``savefig`` would lay it out again at the PDF's
    72 dpi, where the text boxes snap to coarser pixels and the panels move by up to 6.5 pt
    (Figs. 3, 9 and the gap benchmark: 1.9, 2.0 and 3.6 pt; the test publishes the two that move
    most).
    """
    expected_checks = checks_of(name)
    expected = tmp_path / "reference.png"
    save_figure(FIGURES[name](), [expected], tight=False, dpi=PNG_DPI)

    layouts, drawn_at = [], []
    execute, draw = ConstrainedLayoutEngine.execute, Figure.draw

    def counted_execute(engine, figure):
        layouts.append(figure.dpi)
        return execute(engine, figure)

    def recorded_draw(figure, renderer):
        drawn_at.append([ax.get_position().bounds for ax in figure.axes])
        return draw(figure, renderer)

    monkeypatch.setattr(ConstrainedLayoutEngine, "execute", counted_execute)
    monkeypatch.setattr(Figure, "draw", recorded_draw)
    paths = [tmp_path / "published.png", tmp_path / "published.pdf"]
    written = publish_artifact(
        FigureArtifact(name, FIGURES[name](), {}), paths, tmp_path / "published.json"
    )
    assert layouts == [PNG_DPI]
    assert len(drawn_at) == 2 and drawn_at[0] == drawn_at[1]
    assert paths[0].read_bytes() == expected.read_bytes()
    assert paths[1].read_bytes().startswith(b"%PDF")
    # the same verdicts and findings; the count of texts may differ by a tick label, as a
    # locator picks its ticks from the axis length of the layout it sees
    published = {c["id"]: (c["passed"], without_count(c["observed"])) for c in written["checks"]}
    for check in expected_checks:
        observed = without_count(to_jsonable(check.observed))
        assert published[check.id] == (check.passed, observed), check.id


def without_count(observed: dict) -> dict:
    """A reader check's findings without its count of drawn texts."""
    return {key: value for key, value in observed.items() if key != "n_texts"}
