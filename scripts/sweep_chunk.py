"""Rule sweep_chunk: one chunk of the sensitivity sweep's configurations and replicates (§5).

Input   config/reference/faulted_pipeline_seed11_rerun.csv   R's seed-11 signals (if r_signals)
Output  results/sensitivity/chunks/{scatteritem}.json
        {"points": [...], "rows": [...]}: per point, one row per source (ours, r_signals) and
        correction method, columns dtwin.sensitivity_sweep.SWEEP_COLUMNS (RMSE/MAE in m,
        reductions in %)
Params  points (this chunk's alpha, m_A, m_B, replicate), simulation, command, twin, arx,
        sensitivity (seed, hmm, correction.code / .paper, r_signals)
Imports no matplotlib or statsmodels. The points run one after another in this process, each
from its own seed, so a point's rows do not depend on the chunk it falls in.
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_json
from dtwin.config_sections import SweepPointSettings
from dtwin.reference.loaders import load_r_physics
from dtwin.sensitivity_sweep import SweepPoint
from dtwin.stages.sensitivity import sweep_point, sweep_point_on_r_signals

p = snakemake.params
sweep = SweepPointSettings.from_mapping(p.sensitivity)
sections = {"twin": p.twin, "arx": p.arx, "sensitivity": sweep}
r_physics = load_r_physics(snakemake.input.r_pipeline)[0] if sweep.r_signals else None
points, rows = [SweepPoint(**values) for values in p.points], []
for point in points:
    runs = [sweep_point(point, simulation=p.simulation, command=p.command, **sections)]
    if r_physics is not None:
        runs.append(sweep_point_on_r_signals(point, r_physics, **sections))
    rows.extend(row for run in runs for row in run.rows())
write_json({"points": [point._asdict() for point in points], "rows": rows}, snakemake.output.json)
