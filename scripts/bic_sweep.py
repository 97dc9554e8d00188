"""Rule bic_sweep: BIC over K on the nominal residuals and the fault features (paper §5).

Input   results/residuals.csv (nominal e0..e4), results/faults/residuals.csv (faulted e0..e4)
Output  results/bic_sweep.csv   dataset, n_features, K, log_likelihood, n_params, bic,
                                converged, n_usable
Params  bic (ks, n_restarts), hmm (seed, max_iter, tol, var_floor)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.fault_injection import regime_features
from dtwin.stages.regimes import bic_sweep
from dtwin.wiring import RESIDUALS

datasets = {
    "nominal_residuals": pd.read_csv(snakemake.input.residuals)[list(RESIDUALS)],
    "fault_features": regime_features(pd.read_csv(snakemake.input.fault_residuals)),
}
write_csv(bic_sweep(datasets, snakemake.params.bic, snakemake.params.hmm), snakemake.output.table)
