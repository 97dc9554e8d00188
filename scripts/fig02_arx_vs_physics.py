"""Rule fig02_arx_vs_physics: paper Fig. 2, physics vs ARX per module, with the R crosschecks.

Input   results/physics.csv, results/surrogate.csv, results/residuals.csv, results/arx_theta.csv,
        results/arx_crosscheck.json, config/reference/r_numbers.yaml
Output  paper_figures/fig02_arx_vs_physics.{png,pdf,json}
Params  arx (rollout_init is reported)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import load_yaml
from dtwin.config_sections import ArxSettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig02_arx_vs_physics import fig02_arx_vs_physics
from dtwin.reference.crosscheck_result import read_crosscheck

inputs = snakemake.input
artifact = fig02_arx_vs_physics(
    *(pd.read_csv(path) for path in (inputs.physics, inputs.surrogate, inputs.residuals)),
    pd.read_csv(inputs.theta),
    ArxSettings.from_mapping(snakemake.params.arx),
    read_crosscheck(inputs.crosscheck),
    load_yaml(inputs.r_numbers),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
