# Sim-to-real gap diagnosis (docs/gap.md), checked on generated recordings with a withheld effect.
# gap_case (one job per case) -> gap_diagnose (one job per case) -> gap_benchmark (aggregate).
# Config: config["gap"] (docs/gap.md §Settings, §Cases and rules); the case list GAP_CASES is
# built in common.smk.

rule gap_case:
    input:
        lib=dtwin_sources("scripts/gap_case.py"),
    output:
        recording="results/gap/cases/{case}/recording.csv",
        twin="results/gap/cases/{case}/twin.yaml",
        key="results/gap/cases/{case}/key.json",
    params:
        benchmark=config["gap"]["benchmark"],
    log:
        "logs/gap_case/{case}.log",
    benchmark:
        "benchmarks/rules/gap_case/{case}.tsv"
    message:
        "gap: generate the withheld-effect recording {wildcards.case}"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/gap_case.py"


rule gap_diagnose:
    input:
        recording=rules.gap_case.output.recording,
        twin=rules.gap_case.output.twin,
        lib=dtwin_sources("scripts/gap_diagnose.py"),
    output:
        diagnosis="results/gap/diagnoses/{case}/diagnosis.json",
        report="results/gap/diagnoses/{case}/report.md",
        figure="results/gap/diagnoses/{case}/gap.png",
    params:
        diagnose=config["gap"]["diagnose"],
    log:
        "logs/gap_diagnose/{case}.log",
    benchmark:
        "benchmarks/rules/gap_diagnose/{case}.tsv"
    message:
        "gap: diagnose {wildcards.case} (the key stays unread)"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/gap_diagnose.py"


rule gap_benchmark:
    input:
        lib=dtwin_sources("scripts/gap_benchmark.py"),
        diagnoses=expand(rules.gap_diagnose.output.diagnosis, case=GAP_CASES),
        truths=expand(rules.gap_case.output.key, case=GAP_CASES),
    output:
        png=report(
            "paper_figures/gap_benchmark.png",
            caption="../report/gap_benchmark.rst",
            category="Gap diagnosis",
        ),
        pdf="paper_figures/gap_benchmark.pdf",
        json="paper_figures/gap_benchmark.json",
        table="results/gap/benchmark.csv",
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
