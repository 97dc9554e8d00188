"""Rule claims_draws: the paper's single-draw claims judged on one chunk of random draws.

Input   config/reference/classification_summary_K4.csv (R's accuracy, macro-F1, kappa),
        config/reference/r_numbers.yaml (R's held-out RMSE per residual)
Output  results/draws/chunk<c>.json   {"draws": [{draw, seeds, claims: {<artifact>:<id>: bool},
                                       numbers: {accuracy, kappa, drmse_pct (%), ...}}]}
Params  draws (the chunk's draw numbers), sections (simulation, command, twin, arx, faults,
        hmm, correction, mcda), acf (ljungbox_lags, significance, strong_lag1)
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import load_yaml, write_json
from dtwin.stages.draw_claims import judge_draw
from dtwin.reference.loaders import load_r_classification
from dtwin.stages.draws import run_draw

params, inputs = snakemake.params, snakemake.input
r_scores = load_r_classification(inputs.r_summary)
r_rmse = load_yaml(inputs.r_numbers)["nominal_rmse_test_half"]
records = [
    judge_draw(run_draw(draw, params.sections), params.acf, r_scores, r_rmse)
    for draw in params.draws
]
write_json({"draws": records}, snakemake.output.json)
