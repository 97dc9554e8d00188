"""gap_benchmark: score every diagnosis against its withheld truth.

Inputs: ``diagnoses``, ``truths``: the chunk folders of gap_diagnoses and gap_cases; params
``diagnoses`` (diagnosis.json per case) and ``truths`` (key.json per case, same order) name the
files in them.
Outputs: ``paper_figures/gap_benchmark.{png,pdf}`` (drawn by
:mod:`dtwin.figures.gap_benchmark`), ``gap_benchmark.json`` ({artifact, files, figure, metrics,
checks}; the targets of docs/gap.md §Targets are claims), ``results/gap/benchmark.csv`` (one
row per case, columns in :mod:`dtwin.gapbench.scores`). Config: none beyond the case list.
"""

from dtwin._script import start_rule

start_rule(snakemake)


import json
from pathlib import Path

from dtwin.artifacts import write_csv
from dtwin.figures._style import publish_artifact
from dtwin.figures.gap_benchmark import gap_benchmark
from dtwin.gapbench.scores import TARGETS, benchmark_checks, benchmark_metrics, score_cases
from dtwin.gap.effects import NONE

triples = [
    (Path(key).parent.name, json.loads(Path(key).read_text()), json.loads(Path(diag).read_text()))
    for key, diag in zip(snakemake.params.truths, snakemake.params.diagnoses, strict=True)
]
table = score_cases(triples)
metrics = benchmark_metrics(table)
write_csv(table, snakemake.output.table)
checks = benchmark_checks(table, metrics)
artifact = gap_benchmark(table, metrics, checks, TARGETS, NONE)
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
