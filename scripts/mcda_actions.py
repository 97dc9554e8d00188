"""Rule mcda_actions: TOPSIS action per step on the fault scenario (paper §5, Table 1).

Input   results/faults/residuals.csv (t, regime, e0..e4),
        results/faults/posteriors.csv (p_<regime>),
        config/reference/{faulted_pipeline_seed11_rerun,mcda_actions_timeline_rerun}.csv
Output  results/mcda/actions.csv   step, t (s), regime, gate, degenerate, best, best_score,
        confidence, action, score_<action>
        results/mcda/crosscheck.json   legacy mode on R's inputs vs R's RMCDA 0.3.1 timeline
Params  mcda (weights, roll_sec, gate, dwell, margin), dt (s)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.reference.crosscheck_result import write_crosscheck
from dtwin.reference.loaders import load_r_mcda_timeline
from dtwin.reference.mcda_crosscheck import crosscheck_mcda_legacy
from dtwin.stages.decisions import select_mcda_actions

inputs, params = snakemake.input, snakemake.params
result = select_mcda_actions(
    pd.read_csv(inputs.residuals), pd.read_csv(inputs.posteriors), params.mcda, params.dt
)
crosscheck = crosscheck_mcda_legacy(
    inputs.r_pipeline, load_r_mcda_timeline(inputs.r_timeline), params.mcda, params.dt
)
write_csv(result.timeline, snakemake.output.timeline)
write_crosscheck(crosscheck, snakemake.output.crosscheck)
