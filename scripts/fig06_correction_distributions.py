"""Rule fig06_correction_distributions: paper Fig. 6, residual densities before/after.

Input   results/correction/{residuals,metrics}.csv,
        config/reference/targeted_intervention_metrics_rerun.csv
Output  paper_figures/fig06_correction_distributions.{png,pdf,json}
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig06_correction_distributions import fig06_correction_distributions
from dtwin.reference.loaders import load_r_correction_metrics

inputs = snakemake.input
artifact = fig06_correction_distributions(
    pd.read_csv(inputs.residuals),
    pd.read_csv(inputs.metrics),
    load_r_correction_metrics(inputs.r_metrics),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
