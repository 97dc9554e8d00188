"""Rule sweep_point: one configuration and replicate of the sensitivity sweep (paper §5).

Input   config/reference/faulted_pipeline_seed11_rerun.csv   R's seed-11 signals (if r_signals)
Output  results/sensitivity/alpha{alpha}_mA{ma}_mB{mb}_rep{rep}.json
        {"point": {...}, "rows": [...]}: one row per source (ours, r_signals) and correction
        method, columns dtwin.sensitivity_sweep.SWEEP_COLUMNS (RMSE/MAE in m, reductions in %)
Params  point (alpha, m_A, m_B, replicate), simulation, command, twin, arx,
        sensitivity (seed, hmm, correction.code / .paper, r_signals)
Imports no matplotlib or statsmodels: this runs once per grid point.
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_json
from dtwin.reference.loaders import load_r_physics
from dtwin.sensitivity_sweep import SweepPoint
from dtwin.stages.sensitivity import sweep_point, sweep_point_on_r_signals

p = snakemake.params
point = SweepPoint(**p.point)
sections = {"twin": p.twin, "arx": p.arx, "sensitivity": p.sensitivity}
runs = [sweep_point(point, simulation=p.simulation, command=p.command, **sections)]
if p.sensitivity["r_signals"]:
    r_physics, _ = load_r_physics(snakemake.input.r_pipeline)
    runs.append(sweep_point_on_r_signals(point, r_physics, **sections))
rows = [row for run in runs for row in run.rows()]
write_json({"point": point._asdict(), "rows": rows}, snakemake.output.json)
