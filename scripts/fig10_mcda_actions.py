"""Rule fig10_mcda_actions: paper Fig. 10, actions over the true regimes; counts vs R.

Input   results/mcda/actions.csv, results/mcda/crosscheck.json,
        config/reference/mcda_action_counts_rerun.csv
Output  paper_figures/fig10_mcda_actions.{png,pdf,json}
Params  mcda, dt (s)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig10_mcda_actions import fig10_mcda_actions
from dtwin.reference.crosscheck_result import read_crosscheck
from dtwin.reference.loaders import load_r_mcda_counts

inputs = snakemake.input
artifact = fig10_mcda_actions(
    pd.read_csv(inputs.timeline),
    snakemake.params.mcda,
    snakemake.params.dt,
    load_r_mcda_counts(inputs.r_counts),
    read_crosscheck(inputs.crosscheck),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
