"""Rule nominal_regimes: K-state Gaussian HMM on the z-scored nominal residuals (paper §4.2).

Input   results/residuals.csv, config/reference/faulted_pipeline_seed11_rerun.csv,
        config/reference/r_numbers.yaml (the crosscheck fit on R's features)
Output  results/regimes/nominal_states.csv   t (s), state (Viterbi, 1..K), gamma_S1..SK
                                             (smoothed), filtered_S1..SK (filtered posteriors)
        results/regimes/nominal_model.json   parameters (z-units), log-likelihood, BIC, all starts
        results/regimes/crosscheck.json      our EM on R's fault features vs depmixS4
Params  hmm (n_states, n_restarts, seed, max_iter, tol, var_floor)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import load_yaml, write_csv, write_json
from dtwin.reference.crosscheck_result import write_crosscheck
from dtwin.reference.em_crosscheck import crosscheck_r_loglik
from dtwin.stages.regimes import fit_nominal_regimes

inputs, output, hmm = snakemake.input, snakemake.output, snakemake.params.hmm
states, summary = fit_nominal_regimes(pd.read_csv(inputs.residuals), hmm)
r_log_likelihood = load_yaml(inputs.r_numbers)["hmm_fault_k4"]["log_likelihood"]
crosscheck = crosscheck_r_loglik(pd.read_csv(inputs.r_pipeline), hmm, r_log_likelihood)
write_csv(states, output.states)
write_json(summary, output.model)
write_crosscheck(crosscheck, output.crosscheck)
