"""Rule mcda_actions: TOPSIS action per step on the fault scenario (paper §5, Table 1).

Input   results/faults/residuals.csv (t, regime, e0..e4), results/faults/posteriors.csv (p_<regime>)
Output  results/mcda/actions.csv   step, t (s), regime, gate, degenerate, best, best_score,
        confidence, action, score_<action>
Params  mcda (weights, roll_sec, gate, dwell, margin), dt (s)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.decisions import select_mcda_actions

result = select_mcda_actions(
    pd.read_csv(snakemake.input.residuals),
    pd.read_csv(snakemake.input.posteriors),
    snakemake.params.mcda,
    snakemake.params.dt,
)
write_csv(result.timeline, snakemake.output.timeline)
