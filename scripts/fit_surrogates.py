"""Rule fit_surrogates: least-squares ARX fit of M0, M1, M2a, M2b (paper §3.2, Eq. (24)).

Input   results/physics.csv
Output  results/arx_theta.csv   module, na, nb, d, n_train, coef (a1.., b1..), value
Params  arx (orders, train_frac)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.stages.twin import fit_twin_surrogates

theta = fit_twin_surrogates(pd.read_csv(snakemake.input.physics), snakemake.params.arx)
write_csv(theta, snakemake.output.theta, float_format="%.17g")
