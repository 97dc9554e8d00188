"""Rule fit_surrogates: least-squares ARX fit of M0, M1, M2a, M2b (paper §3.2, Eq. (24)).

Input   results/physics.csv,
        config/reference/{faulted_pipeline_seed11_rerun,arx_theta_seed11_rerun}.csv
Output  results/arx_theta.csv         module, na, nb, d, n_train, coef (a1.., b1..), value
        results/arx_crosscheck.json   the same fit and rollout on R's signals vs R's
Params  arx (orders, train_frac), twin (the crosscheck's rollout)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.artifacts import write_csv
from dtwin.config_sections import ArxSettings
from dtwin.params import twin_params_from_mapping
from dtwin.reference.arx_crosscheck import crosscheck_arx
from dtwin.reference.crosscheck_result import write_crosscheck
from dtwin.stages.twin import fit_twin_surrogates

inputs, arx = snakemake.input, ArxSettings.from_mapping(snakemake.params.arx)
theta = fit_twin_surrogates(pd.read_csv(inputs.physics), arx)
crosscheck = crosscheck_arx(
    inputs.r_pipeline,
    inputs.r_theta,
    arx.orders,
    arx.train_frac,
    twin_params_from_mapping(snakemake.params.twin),
)
write_csv(theta, snakemake.output.theta, float_format="%.17g")
write_crosscheck(crosscheck, snakemake.output.crosscheck)
