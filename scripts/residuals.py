"""Rule residuals: roll the surrogate chain out and take module residuals (paper Eq. (1)).

Input   results/physics.csv, results/arx_theta.csv
Output  results/surrogate.csv   t and the twin's signals (v = backward difference of x)
        results/residuals.csv   t, e0, e1, e2a, e2b, e3, e4 (surrogate - physics)
Params  twin, rollout_init ("physics" or "zeros")
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.twin import roll_out_twin

surrogate, residuals = roll_out_twin(
    pd.read_csv(snakemake.input.physics),
    pd.read_csv(snakemake.input.theta),
    snakemake.params.twin,
    snakemake.params.rollout_init,
)
write_csv(surrogate, snakemake.output.surrogate)
write_csv(residuals, snakemake.output.residuals)
