"""Stage "correction" (paper §4.3): targeted_intervention on the fault scenario → Figs. 5, 6."""


rule targeted_intervention:
    message:
        "Correcting the faulted twin with the posterior-weighted state bias "
        "(kappa {params.correction[kappa]}, smoothed and filtered posteriors)"
    input:
        lib=dtwin_sources("scripts/targeted_intervention.py"),
        physics=rules.simulate.output.physics,
        surrogate=rules.fault_regimes.output.surrogate,
        states=rules.fault_regimes.output.states,
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_metrics=f"{REFERENCE_DIR}/targeted_intervention_metrics_rerun.csv",
    output:
        residuals="results/correction/residuals.csv",
        metrics="results/correction/metrics.csv",
        crosscheck="results/correction/crosscheck.json",
    params:
        correction=config["correction"],
        twin={k: config["twin"][k] for k in ("dt", "fusion", "kpi")},
    log:
        "logs/targeted_intervention.log",
    benchmark:
        "benchmarks/rules/targeted_intervention.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/targeted_intervention.py"


rule fig05_correction_timeseries:
    message:
        "Drawing paper Fig. 5 (residuals before/after) beside R's table and the crosscheck"
    input:
        lib=dtwin_sources("scripts/fig05_correction_timeseries.py"),
        residuals=rules.targeted_intervention.output.residuals,
        metrics=rules.targeted_intervention.output.metrics,
        crosscheck=rules.targeted_intervention.output.crosscheck,
        r_metrics=f"{REFERENCE_DIR}/targeted_intervention_metrics_rerun.csv",
    output:
        png=report(
            "paper_figures/fig05_correction_timeseries.png",
            caption="../report/fig05_correction_timeseries.rst",
            category="§4.3 Targeted intervention",
        ),
        pdf="paper_figures/fig05_correction_timeseries.pdf",
        json="paper_figures/fig05_correction_timeseries.json",
    params:
        correction=config["correction"],
    log:
        "logs/fig05_correction_timeseries.log",
    benchmark:
        "benchmarks/rules/fig05_correction_timeseries.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig05_correction_timeseries.py"


rule fig06_correction_distributions:
    message:
        "Drawing paper Fig. 6 (residual densities before/after the correction)"
    input:
        lib=dtwin_sources("scripts/fig06_correction_distributions.py"),
        residuals=rules.targeted_intervention.output.residuals,
        metrics=rules.targeted_intervention.output.metrics,
        r_metrics=f"{REFERENCE_DIR}/targeted_intervention_metrics_rerun.csv",
    output:
        png=report(
            "paper_figures/fig06_correction_distributions.png",
            caption="../report/fig06_correction_distributions.rst",
            category="§4.3 Targeted intervention",
        ),
        pdf="paper_figures/fig06_correction_distributions.pdf",
        json="paper_figures/fig06_correction_distributions.json",
    log:
        "logs/fig06_correction_distributions.log",
    benchmark:
        "benchmarks/rules/fig06_correction_distributions.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig06_correction_distributions.py"
