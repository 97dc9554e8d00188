"""Rule bic_sweep_dataset: BIC over K on one data set (paper §5), one job per data set.

Input   features: results/residuals.csv (nominal e0..e4) or results/faults/residuals.csv
        (faulted e0..e4, turned into the ten fault features); model:
        results/regimes/nominal_model.json or results/faults/summary.json (the dedicated
        K = 4 fit of Fig. 4 or 7: the sweep's point at K = 4, so figure and curve share a fit)
Output  results/bic/<dataset>.csv   the rows of results/bic_sweep.csv for this data set
Params  dataset (nominal_residuals or fault_features), bic (ks, k_max, stop_after_rises,
        n_restarts, max_restarts, split_starts), hmm (seed, max_iter, tol, var_floor)
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_csv
from dtwin.stages.regimes import bic_sweep_dataset

inputs, params = snakemake.input, snakemake.params
table = bic_sweep_dataset(
    snakemake.wildcards.dataset, inputs.features, inputs.model, params.bic, params.hmm
)
write_csv(table, snakemake.output.table)
