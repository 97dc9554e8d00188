"""Rule fault_regimes: fault injection, ten features, K-state HMM, Hungarian scoring (§4.4).

Input   results/physics.csv, results/surrogate.csv
Output  results/faults/surrogate.csv   t, regime, faulted surrogate signals (u_act, x (m), ...)
        results/faults/residuals.csv   t, regime, e0, e1, e2a, e2b, e3, e4 (faulted − physics)
        results/faults/states.csv      t, regime, state (Viterbi, 1..K), gamma_S*, filtered_S*
        results/faults/posteriors.csv  t, regime, state, mapped_regime, p_Nominal,
                                       p_SensorNoisy, p_DynamicsOff, p_Drift (Hungarian-mapped
                                       smoothed posteriors, rows sum to 1)
        results/faults/summary.json    model, mapping, scores, per-start scores; both origins
Params  faults (schedule, magnitudes, drift_origin, seed), hmm, twin (dt, fusion, kpi)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv, write_json
from dtwin.stages.faults import run_fault_scenario

params, output = snakemake.params, snakemake.output
scenario = run_fault_scenario(
    pd.read_csv(snakemake.input.physics),
    pd.read_csv(snakemake.input.surrogate),
    params.faults,
    params.hmm,
    params.twin,
)
write_csv(scenario.surrogate, output.surrogate)
write_csv(scenario.residuals, output.residuals)
write_csv(scenario.states, output.states)
write_csv(scenario.posteriors, output.posteriors)
write_json(scenario.summary, output.summary)
