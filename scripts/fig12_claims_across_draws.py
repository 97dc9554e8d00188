"""Rule fig12_claims_across_draws: the paper's claims across random draws (issue 12).

Input   results/draws/chunk<c>.json (every chunk), R's seed-11 fault scenario, correction
        metrics and classification scores (config/reference/)
Output  paper_figures/fig12_claims_across_draws.{png,pdf,json},
        results/draws/draws.csv   one row per draw: draw, seeds, headline numbers (scores,
                                  dRMSE % per residual, DynamicsOff mean x (m), action shares)
Params  draws (n_draws, interval)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

from dtwin.artifacts import load_yaml, write_csv
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig12_claims_across_draws import fig12_claims_across_draws, r_draw_values
from dtwin.reference.loaders import (
    load_r_classification,
    load_r_correction_metrics,
    load_r_faulted_twin,
    load_r_fault_scenario,
)

inputs, draws = snakemake.input, snakemake.params.draws
r_physics, _, _ = load_r_faulted_twin(inputs.r_pipeline)
r_residuals, _ = load_r_fault_scenario(inputs.r_pipeline)
r_values = r_draw_values(
    r_physics,
    r_residuals,
    load_r_correction_metrics(inputs.r_metrics),
    load_r_classification(inputs.r_summary),
    load_yaml(inputs.r_numbers),
)
artifact, table = fig12_claims_across_draws(
    [json.loads(Path(p).read_text()) for p in inputs.chunks],
    draws["n_draws"],
    draws["interval"],
    r_values,
)
write_csv(table, snakemake.output.table)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
