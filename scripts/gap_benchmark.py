"""gap_benchmark: score every diagnosis against its withheld truth.

Inputs: ``diagnoses`` (diagnosis.json per case), ``truths`` (key.json per case, same order).
Outputs: ``paper_figures/gap_benchmark.{png,pdf}`` (confusion matrix, accuracy vs magnitude,
shrink per effect), ``gap_benchmark.json`` ({artifact, files, metrics, checks}; the targets of
docs/gap.md §Targets are claims), ``results/gap/benchmark.csv`` (one row per case, columns in
:mod:`dtwin.gap.benchmark`). Config: none beyond the case list.
"""

from dtwin._script import start_rule

start_rule(snakemake)


import json
from pathlib import Path

from dtwin.artifacts import write_artifact, write_csv
from dtwin.gap.benchmark import benchmark_checks, benchmark_metrics, draw_benchmark, score_cases

triples = [
    (Path(key).parent.name, json.loads(Path(key).read_text()), json.loads(Path(diag).read_text()))
    for key, diag in zip(snakemake.input.truths, snakemake.input.diagnoses, strict=True)
]
table = score_cases(triples)
metrics = benchmark_metrics(table)
write_csv(table, snakemake.output.table)
figures = [snakemake.output.png, snakemake.output.pdf]
draw_benchmark(table, metrics, figures)
checks = benchmark_checks(table, metrics)
write_artifact(snakemake.output.json, "gap_benchmark", figures, metrics, checks)
