"""Rule nominal_regimes: K-state Gaussian HMM on the z-scored nominal residuals (paper §4.2).

Input   results/residuals.csv
Output  results/regimes/nominal_states.csv   t (s), state (Viterbi, 1..K), gamma_S1..SK
                                             (smoothed), filtered_S1..SK (filtered posteriors)
        results/regimes/nominal_model.json   parameters (z-units), log-likelihood, BIC, all starts
Params  hmm (n_states, n_restarts, seed, max_iter, tol, var_floor)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv, write_json
from dtwin.stages.regimes import fit_nominal_regimes

states, summary = fit_nominal_regimes(pd.read_csv(snakemake.input.residuals), snakemake.params.hmm)
write_csv(states, snakemake.output.states)
write_json(summary, snakemake.output.model)
