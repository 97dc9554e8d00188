"""Rule ar_hmm_sweep: the AR(1)-emission HMM's BIC over K on the fault features (§5 future work).

Input   results/faults/residuals.csv   t, regime, e0..e4 (the fault scenario of Fig. 7)
Output  results/ar_hmm/bic.csv         K, log_likelihood, n_params ((K-1)+K(K-1)+3DK), bic,
                                       converged, n_usable, log_likelihood_half, n_starts,
                                       source, accuracy, macro_f1, kappa (Hungarian, per K)
        results/ar_hmm/summary.json    settings, k_star, bracketed, scores and per-state AR
                                       coefficients at K = hmm.n_states
Params  ar_hmm (seed, ks, k_max, stop_after_rises, n_restarts, max_iter, tol, var_floor),
        n_states (hmm.n_states)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv, write_json
from dtwin.stages.ar_regimes import ar_regime_sweep

table, summary = ar_regime_sweep(
    pd.read_csv(snakemake.input.residuals), snakemake.params.ar_hmm, snakemake.params.n_states
)
write_csv(table, snakemake.output.table)
write_json(summary, snakemake.output.summary)
