"""Rule fig05_correction_timeseries: paper Fig. 5, residuals before/after the correction.

Input   results/correction/{residuals,metrics,crosscheck}.{csv,csv,json},
        config/reference/targeted_intervention_metrics_rerun.csv
Output  paper_figures/fig05_correction_timeseries.{png,pdf,json}
Params  correction (reported in the metrics)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig05_correction_timeseries import fig05_correction_timeseries
from dtwin.reference.crosscheck_result import read_crosscheck
from dtwin.reference.loaders import load_r_correction_metrics

inputs = snakemake.input
artifact = fig05_correction_timeseries(
    pd.read_csv(inputs.residuals),
    pd.read_csv(inputs.metrics),
    load_r_correction_metrics(inputs.r_metrics),
    read_crosscheck(inputs.crosscheck),
    snakemake.params.correction,
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
