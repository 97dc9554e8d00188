"""Rule fig04_hmm_posteriors: paper Fig. 4, smoothed and filtered posteriors of the nominal HMM.

Input   results/regimes/nominal_states.csv, results/regimes/nominal_model.json,
        config/reference/faulted_pipeline_seed11_rerun.csv (crosscheck fit), r_numbers.yaml
Output  paper_figures/fig04_hmm_posteriors.{png,pdf,json}
Params  hmm (the crosscheck fit on R's features uses its starts and EM options)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json

import pandas as pd

from dtwin.artifacts import load_yaml
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig04_hmm_posteriors import fig04_hmm_posteriors

inputs = snakemake.input
with open(inputs.model, encoding="utf-8") as handle:
    summary = json.load(handle)
artifact = fig04_hmm_posteriors(
    pd.read_csv(inputs.states),
    summary,
    snakemake.params.hmm,
    pd.read_csv(inputs.r_pipeline),
    load_yaml(inputs.r_numbers),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
