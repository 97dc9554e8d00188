"""Rule fig12_claims_across_draws: the paper's claims across random draws.

Input   results/draws/chunk<c>.json (every chunk), results/draws/bic/chunk<c>.json (every
        chunk of BIC sweeps), results/bic_sweep.csv (the main run's), R's seed-11 fault
        scenario, correction metrics and classification scores (config/reference/)
Output  paper_figures/fig12_claims_across_draws.{png,pdf,json},
        results/draws/draws.csv   one row per draw: draw, seeds, headline numbers (scores,
                                  dRMSE % per residual, DynamicsOff mean x (m), action shares)
        results/draws/k_star.csv  one row per draw and data set: K*, largest K fitted,
                                  bracketed, max_gain (log-likelihood of the second half of
                                  the starts, up to K* + 2), stable, n_starts, k4_given
Params  draws (n_draws, interval), bic_draws (draws with a BIC sweep), main_n_restarts
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

import pandas as pd

from dtwin.artifacts import load_yaml, write_csv
from dtwin.config_sections import DrawsSettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig12_claims_across_draws import (
    BicDraws,
    fig12_claims_across_draws,
    r_draw_values,
)
from dtwin.reference.loaders import (
    load_r_classification,
    load_r_correction_metrics,
    load_r_faulted_twin,
    load_r_fault_scenario,
)

inputs, draws = snakemake.input, DrawsSettings.from_mapping(snakemake.params.draws)
r_physics, _, _ = load_r_faulted_twin(inputs.r_pipeline)
r_residuals, _ = load_r_fault_scenario(inputs.r_pipeline)
r_values = r_draw_values(
    r_physics,
    r_residuals,
    load_r_correction_metrics(inputs.r_metrics),
    load_r_classification(inputs.r_summary),
    load_yaml(inputs.r_numbers),
)
bic = BicDraws(
    [json.loads(Path(p).read_text()) for p in inputs.bic_chunks],
    snakemake.params.bic_draws,
    pd.read_csv(inputs.bic_main),
    snakemake.params.main_n_restarts,
)
artifact, table, k_star = fig12_claims_across_draws(
    [json.loads(Path(p).read_text()) for p in inputs.chunks],
    draws.n_draws,
    draws.interval,
    r_values,
    bic,
)
write_csv(table, snakemake.output.table)
write_csv(k_star, snakemake.output.k_star)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
