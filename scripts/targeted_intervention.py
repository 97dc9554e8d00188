"""Rule targeted_intervention: posterior-weighted bias correction of the faulted twin (§4.3).

Input   results/physics.csv, results/faults/surrogate.csv, results/faults/states.csv
Output  results/correction/residuals.csv   t, regime, <e>_before, <e>_smoothed, <e>_filtered
                                           for e in e0..e4 (physical units)
        results/correction/metrics.csv     variant (smoothed|filtered), channel, rmse_before,
                                           rmse_after, mae_before, mae_after, drmse_pct, dmae_pct
Params  correction (kappa, ema_alpha, rate_max), twin (dt, fusion, kpi)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.correction import targeted_intervention

inputs = snakemake.input
residuals, metrics = targeted_intervention(
    pd.read_csv(inputs.physics),
    pd.read_csv(inputs.surrogate),
    pd.read_csv(inputs.states),
    snakemake.params.twin,
    snakemake.params.correction,
)
write_csv(residuals, snakemake.output.residuals)
write_csv(metrics, snakemake.output.metrics)
