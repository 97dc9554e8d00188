"""Stage "faults" (paper §4.4): fault_regimes → Figs. 7, 8.

fault_regimes writes the contract tables results/faults/residuals.csv and
results/faults/posteriors.csv (column names documented in scripts/fault_regimes.py) that the
correction, BIC and decision stages read.
"""


rule fault_regimes:
    message:
        "Injecting the fault schedule (drift origin {params.faults[drift_origin]}), fitting the "
        "K={params.hmm[n_states]} HMM ({params.hmm[n_restarts]} starts) and scoring it"
    input:
        lib=dtwin_sources("scripts/fault_regimes.py"),
        physics=rules.simulate.output.physics,
        surrogate=rules.residuals.output.surrogate,
    output:
        surrogate="results/faults/surrogate.csv",
        residuals="results/faults/residuals.csv",
        states="results/faults/states.csv",
        posteriors="results/faults/posteriors.csv",
        summary="results/faults/summary.json",
    params:
        faults=config["faults"],
        hmm=config["hmm"],
        twin={k: config["twin"][k] for k in ("dt", "fusion", "kpi")},
    log:
        "logs/fault_regimes.log",
    benchmark:
        "benchmarks/rules/fault_regimes.tsv"
    priority: PRIORITY_FAULT_FIT
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fault_regimes.py"


rule fig07_fault_posteriors:
    message:
        "Drawing paper Fig. 7 (mapped posteriors) and crosschecking the Hungarian mapping on R's path"
    input:
        lib=dtwin_sources("scripts/fig07_fault_posteriors.py"),
        posteriors=rules.fault_regimes.output.posteriors,
        summary=rules.fault_regimes.output.summary,
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_confusion=f"{REFERENCE_DIR}/hungarian_confusion_K4_diag.csv",
        r_summary=f"{REFERENCE_DIR}/classification_summary_K4.csv",
        r_multistart=f"{REFERENCE_DIR}/multistart_restarts_K4.csv",
    output:
        png=report(
            "paper_figures/fig07_fault_posteriors.png",
            caption="../report/fig07_fault_posteriors.rst",
            category="§4.4 Fault injection",
        ),
        pdf="paper_figures/fig07_fault_posteriors.pdf",
        json="paper_figures/fig07_fault_posteriors.json",
    log:
        "logs/fig07_fault_posteriors.log",
    benchmark:
        "benchmarks/rules/fig07_fault_posteriors.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig07_fault_posteriors.py"


rule fig08_feature_separability:
    message:
        "Drawing paper Fig. 8 (the ten z-scored features by regime)"
    input:
        lib=dtwin_sources("scripts/fig08_feature_separability.py"),
        residuals=rules.fault_regimes.output.residuals,
    output:
        png=report(
            "paper_figures/fig08_feature_separability.png",
            caption="../report/fig08_feature_separability.rst",
            category="§4.4 Fault injection",
        ),
        pdf="paper_figures/fig08_feature_separability.pdf",
        json="paper_figures/fig08_feature_separability.json",
    log:
        "logs/fig08_feature_separability.log",
    benchmark:
        "benchmarks/rules/fig08_feature_separability.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig08_feature_separability.py"
