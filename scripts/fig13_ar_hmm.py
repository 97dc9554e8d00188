"""Rule fig13_ar_hmm: the AR(1)-emission HMM beside the Gaussian HMM (§5 future work).

Input   results/ar_hmm/bic.csv, results/ar_hmm/summary.json (ar_hmm_sweep),
        results/bic_sweep.csv (the Gaussian HMM's BIC), results/faults/summary.json (its
        Hungarian scores at K = hmm.n_states)
Output  paper_figures/fig13_ar_hmm.{png,pdf,json}
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig13_ar_hmm import fig13_ar_hmm

inputs = snakemake.input
artifact = fig13_ar_hmm(
    pd.read_csv(inputs.ar_table),
    json.loads(Path(inputs.ar_summary).read_text()),
    pd.read_csv(inputs.gaussian_table),
    json.loads(Path(inputs.fault_summary).read_text()),
)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
