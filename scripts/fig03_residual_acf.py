"""Rule fig03_residual_acf: paper Fig. 3 A-D, white noise vs structured residuals, Ljung-Box.

Input   results/residuals.csv, config/reference/r_numbers.yaml
Output  paper_figures/fig03_residual_acf.{png,pdf,json}
Params  acf (nlags, white-noise demo, Ljung-Box lags, thresholds)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import load_yaml
from dtwin.config_sections import AcfSettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig03_residual_acf import fig03_residual_acf

artifact = fig03_residual_acf(
    pd.read_csv(snakemake.input.residuals),
    AcfSettings.from_mapping(snakemake.params.acf),
    load_yaml(snakemake.input.r_numbers),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
