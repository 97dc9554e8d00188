"""Rule fig07_fault_posteriors: paper Fig. 7, Hungarian-mapped posteriors with the schedule.

Input   results/faults/posteriors.csv, results/faults/summary.json,
        config/reference/{faulted_pipeline_seed11_rerun, hungarian_confusion_K4_diag,
        classification_summary_K4, multistart_restarts_K4}.csv
Output  paper_figures/fig07_fault_posteriors.{png,pdf,json}
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig07_fault_posteriors import fig07_fault_posteriors

inputs = snakemake.input
with open(inputs.summary, encoding="utf-8") as handle:
    summary = json.load(handle)
artifact = fig07_fault_posteriors(
    pd.read_csv(inputs.posteriors),
    summary,
    pd.read_csv(inputs.r_pipeline),
    pd.read_csv(inputs.r_confusion, index_col=0),
    pd.read_csv(inputs.r_summary),
    pd.read_csv(inputs.r_multistart),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
