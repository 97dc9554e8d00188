"""Rule targeted_intervention: posterior-weighted bias correction of the faulted twin (§4.3).

Input   results/physics.csv, results/faults/surrogate.csv, results/faults/states.csv,
        config/reference/{faulted_pipeline_seed11_rerun,targeted_intervention_metrics_rerun}.csv
Output  results/correction/residuals.csv   t, regime, <e>_before, <e>_smoothed, <e>_filtered
                                           for e in e0..e4 (physical units)
        results/correction/metrics.csv     variant (smoothed|filtered), channel, rmse_before,
                                           rmse_after, mae_before, mae_after, drmse_pct, dmae_pct
        results/correction/crosscheck.json the same correction on R's signals vs R's table
Params  correction (kappa, ema_alpha, rate_max), twin (dt, fusion, kpi)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.reference.correction_crosscheck import crosscheck_correction
from dtwin.reference.crosscheck_result import write_crosscheck
from dtwin.reference.loaders import load_r_correction_metrics
from dtwin.stages.correction import targeted_intervention

inputs, params = snakemake.input, snakemake.params
residuals, metrics = targeted_intervention(
    pd.read_csv(inputs.physics),
    pd.read_csv(inputs.surrogate),
    pd.read_csv(inputs.states),
    params.twin,
    params.correction,
)
crosscheck = crosscheck_correction(
    inputs.r_pipeline, load_r_correction_metrics(inputs.r_metrics), params.twin, params.correction
)
write_csv(residuals, snakemake.output.residuals)
write_csv(metrics, snakemake.output.metrics)
write_crosscheck(crosscheck, snakemake.output.crosscheck)
