"""Rule bic_sweep: BIC over K on the nominal residuals and the fault features (paper §5).

Input   results/residuals.csv (nominal e0..e4), results/faults/residuals.csv (faulted e0..e4),
        results/regimes/nominal_model.json, results/faults/summary.json (the dedicated K = 4
        fits of Figs. 4 and 7: the sweep's points at K = 4, so figures and curve share a fit)
Output  results/bic_sweep.csv   dataset, n_features, K, log_likelihood, n_params, bic,
                                converged, n_usable, log_likelihood_half (best of the first
                                half of the starts), n_starts, source (sweep or given)
Params  bic (ks, k_max, stop_after_rises, n_restarts), hmm (seed, max_iter, tol, var_floor)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.fault_injection import regime_features
from dtwin.stages.regimes import bic_sweep
from dtwin.wiring import RESIDUALS

inputs = snakemake.input
datasets = {
    "nominal_residuals": pd.read_csv(inputs.residuals)[list(RESIDUALS)],
    "fault_features": regime_features(pd.read_csv(inputs.fault_residuals)),
}
models = {
    "nominal_residuals": json.loads(Path(inputs.nominal_model).read_text()),
    "fault_features": json.loads(Path(inputs.fault_summary).read_text())["model"],
}
table = bic_sweep(datasets, snakemake.params.bic, snakemake.params.hmm, models)
write_csv(table, snakemake.output.table)
