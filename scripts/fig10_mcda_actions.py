"""Rule fig10_mcda_actions: paper Fig. 10, actions over the true regimes; counts vs R.

Input   results/mcda/actions.csv; R's seed-11 pipeline, MCDA timeline and counts (config/reference)
Output  paper_figures/fig10_mcda_actions.{png,pdf,json}
Params  mcda, dt (s)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig10_mcda_actions import fig10_mcda_actions

inputs = snakemake.input
artifact = fig10_mcda_actions(
    pd.read_csv(inputs.timeline),
    snakemake.params.mcda,
    snakemake.params.dt,
    inputs.r_pipeline,
    inputs.r_timeline,
    inputs.r_counts,
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
