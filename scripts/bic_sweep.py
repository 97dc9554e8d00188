"""Rule bic_sweep: the BIC over K of both data sets in one table (paper §5, Fig. 9).

Input   results/bic/nominal_residuals.csv, results/bic/fault_features.csv (rule
        bic_sweep_dataset: the two sweeps run as two jobs, side by side)
Output  results/bic_sweep.csv   dataset, n_features, K, log_likelihood, n_params, bic,
                                converged, n_usable, log_likelihood_half (best of the first
                                half of the starts), n_starts, n_split_starts, source (sweep or
                                given); nominal residuals first
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.bic_table import bic_sweep

tables = [pd.read_csv(path) for path in snakemake.input.tables]
write_csv(bic_sweep(tables), snakemake.output.table)
