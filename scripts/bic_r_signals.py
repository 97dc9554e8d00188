"""Rule bic_r_signals: Fig. 9's BIC sweep of one data set on R's own seed-11 signals.

Input   config/reference/faulted_pipeline_seed11_rerun.csv (R's signals and residuals)
Output  results/bic/r_signals/{dataset}.csv   the sweep's table (bic_sweep's columns)
Params  bic (ks, k_max, stop_after_rises, n_restarts, max_restarts, split_starts),
        hmm (seed, max_iter, tol, var_floor, engine), twin (dt, fusion, kpi: the nominal
        residuals' surrogate fusion and KPI)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.regimes import bic_r_signals

r_pipeline = pd.read_csv(snakemake.input.r_pipeline)
params = snakemake.params
table = bic_r_signals(snakemake.wildcards.dataset, r_pipeline, params.bic, params.hmm, params.twin)
write_csv(table, snakemake.output.table)
