"""Rule fig11_sensitivity: paper Fig. 11 from every sweep job, beside R's re-run.

Input   results/sensitivity/alpha*_mA*_mB*_rep*.json (one per grid point and replicate),
        config/reference/sensitivity_36_rerun.csv (R's 36 runs)
Output  paper_figures/fig11_sensitivity.{png,pdf,json}
        results/sensitivity/runs.csv      every run (dtwin.sensitivity_sweep.SWEEP_COLUMNS)
        results/sensitivity/summary.csv   mean and interval over replicates per configuration (%)
Params  sensitivity (grid, n_replicates, correction.method, interval, ...)
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_csv
from dtwin.config_sections import SensitivitySettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig11_sensitivity import fig11_sensitivity
from dtwin.reference.loaders import load_r_sweep
from dtwin.sensitivity_sweep import read_sweep_rows, summarize_sweep, sweep_table

s = SensitivitySettings.from_mapping(snakemake.params.sensitivity)
table = sweep_table(read_sweep_rows(snakemake.input.runs), s.grid())
summary = summarize_sweep(table, s.interval)
write_csv(table, snakemake.output.runs)
write_csv(summary, snakemake.output.summary)
artifact = fig11_sensitivity(table, summary, load_r_sweep(snakemake.input.r_sweep), s)
outputs = snakemake.output
publish_artifact(artifact, [outputs.png, outputs.pdf], outputs.json)
