# Sim-to-real gap diagnosis (docs/gap.md), checked on generated recordings with a withheld effect.
# gap_cases (one job per chunk of cases) -> gap_diagnoses (one job per chunk) -> gap_benchmark
# (aggregate). Chunks: Snakemake scattergather "gap" (`--set-scatter gap=N`, see common.smk).
# Config: config["gap"] (docs/gap.md §Settings, §Cases and rules); the case list GAP_CASES is
# built in common.smk.

rule gap_cases:
    input:
        lib=dtwin_sources("scripts/gap_cases.py"),
    output:
        folder=directory("results/gap/cases/{scatteritem}"),
    params:
        cases=gap_cases_of_chunk,
        benchmark=config["gap"]["benchmark"],
        twin=config["twin"],
    log:
        "logs/gap_cases/{scatteritem}.log",
    benchmark:
        "benchmarks/rules/gap_cases/{scatteritem}.tsv"
    message:
        "gap: generate the withheld-effect recordings of chunk {wildcards.scatteritem}"
    threads: 1
    resources:
        mem_mb=500,
        runtime=gap_chunk_runtime,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/gap_cases.py"


rule gap_diagnoses:
    input:
        cases=rules.gap_cases.output.folder,
        lib=dtwin_sources("scripts/gap_diagnoses.py"),
    output:
        folder=directory("results/gap/diagnoses/{scatteritem}"),
    params:
        cases=gap_cases_of_chunk,
        diagnose=config["gap"]["diagnose"],
    log:
        "logs/gap_diagnoses/{scatteritem}.log",
    benchmark:
        "benchmarks/rules/gap_diagnoses/{scatteritem}.tsv"
    message:
        "gap: diagnose the recordings of chunk {wildcards.scatteritem} (the keys stay unread)"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=gap_chunk_runtime,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/gap_diagnoses.py"


rule gap_benchmark:
    input:
        lib=dtwin_sources("scripts/gap_benchmark.py"),
        diagnoses=expand(rules.gap_diagnoses.output.folder, scatteritem=gap_chunks()),
        truths=expand(rules.gap_cases.output.folder, scatteritem=gap_chunks()),
    output:
        png=report(
            "paper_figures/gap_benchmark.png",
            caption="../report/gap_benchmark.rst",
            category="Gap diagnosis",
        ),
        pdf="paper_figures/gap_benchmark.pdf",
        json="paper_figures/gap_benchmark.json",
        table="results/gap/benchmark.csv",
    params:
        diagnoses=gap_case_files("diagnoses", "diagnosis.json"),
        truths=gap_case_files("cases", "key.json"),
    log:
        "logs/gap_benchmark.log",
    benchmark:
        "benchmarks/rules/gap_benchmark.tsv"
    message:
        "gap: score every diagnosis against its withheld truth"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/gap_benchmark.py"
