"""Rule fig04_hmm_posteriors: paper Fig. 4, smoothed and filtered posteriors of the nominal HMM.

Input   results/regimes/nominal_states.csv, results/regimes/nominal_model.json,
        results/regimes/crosscheck.json, config/reference/r_numbers.yaml
Output  paper_figures/fig04_hmm_posteriors.{png,pdf,json}
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json

import pandas as pd

from dtwin.artifacts import load_yaml
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig04_hmm_posteriors import fig04_hmm_posteriors
from dtwin.reference.crosscheck_result import read_crosscheck

inputs = snakemake.input
with open(inputs.model, encoding="utf-8") as handle:
    summary = json.load(handle)
artifact = fig04_hmm_posteriors(
    pd.read_csv(inputs.states),
    summary,
    read_crosscheck(inputs.crosscheck),
    load_yaml(inputs.r_numbers),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
