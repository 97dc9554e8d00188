"""Rule fig05_correction_timeseries: paper Fig. 5, residuals before/after the correction.

Input   results/correction/{residuals,metrics}.csv,
        config/reference/{targeted_intervention_metrics_rerun,faulted_pipeline_seed11_rerun}.csv
Output  paper_figures/fig05_correction_timeseries.{png,pdf,json}
Params  correction, twin (dt, fusion, kpi) — for the crosscheck on R's signals
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig05_correction_timeseries import fig05_correction_timeseries

inputs = snakemake.input
artifact = fig05_correction_timeseries(
    pd.read_csv(inputs.residuals),
    pd.read_csv(inputs.metrics),
    pd.read_csv(inputs.r_metrics),
    inputs.r_pipeline,
    snakemake.params.twin,
    snakemake.params.correction,
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
