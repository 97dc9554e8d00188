"""Rule simulate: run the physical asset (paper §3.1).

Output  results/physics.csv   t (s), u_cmd, u_act, x (m), v (m/s), y_A, y_B, y_fused, z
Params  simulation (T, seed), command, twin
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_csv
from dtwin.stages.twin import simulate_asset

physics = simulate_asset(
    snakemake.params.simulation, snakemake.params.command, snakemake.params.twin
)
write_csv(physics, snakemake.output.physics)
