"""Rule fig09_bic: paper Fig. 9, BIC against K for both data sets, beside R's.

Input   results/bic_sweep.csv, results/bic/r_signals/{dataset}.csv (the sweeps on R's own
        seed-11 signals),
        config/reference/{bic_vs_K_6ch_nofault_singlefit_rerun,
        bic_vs_K_10feat_faulted_multistart5}.csv, r_numbers.yaml
Output  paper_figures/fig09_bic.{png,pdf,json}
Params  bic (the section: n_restarts is reported, k_max named in a note)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import load_yaml
from dtwin.config_sections import BicSettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig09_bic import fig09_bic
from dtwin.reference.bic_crosscheck import crosscheck_bic_formula
from dtwin.reference.loaders import load_r_bic

inputs = snakemake.input
r_log_likelihood = load_yaml(inputs.r_numbers)["bic_nominal_log_likelihood"]
r_tables = load_r_bic(inputs.r_nominal, inputs.r_features, r_log_likelihood)
artifact = fig09_bic(
    pd.read_csv(inputs.table),
    r_tables,
    crosscheck_bic_formula(r_tables, r_log_likelihood),
    BicSettings.from_mapping(snakemake.params.bic),
    pd.concat([pd.read_csv(path) for path in inputs.r_signals], ignore_index=True),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
