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
from dtwin.reference.hungarian_crosscheck import crosscheck_hungarian
from dtwin.reference.loaders import load_r_classification, load_r_confusion

inputs = snakemake.input
with open(inputs.summary, encoding="utf-8") as handle:
    summary = json.load(handle)
r_scores = load_r_classification(inputs.r_summary)
crosscheck = crosscheck_hungarian(
    pd.read_csv(inputs.r_pipeline), load_r_confusion(inputs.r_confusion), r_scores
)
artifact = fig07_fault_posteriors(
    pd.read_csv(inputs.posteriors), summary, r_scores, pd.read_csv(inputs.r_multistart), crosscheck
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
