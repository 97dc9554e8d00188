"""Stage "regimes" (paper §4.2, §5): nominal_regimes → Fig. 4; bic_sweep → Fig. 9.

bic_sweep_dataset runs the BIC sweep of each data set as its own job (the two run side by
side); bic_sweep joins them. The fault features' sweep reads the fault scenario, so faults.smk
is included first.
"""


rule nominal_regimes:
    message:
        "Fitting the K={params.hmm[n_states]} HMM to the nominal residuals "
        "({params.hmm[n_restarts]} EM starts) and crosschecking the EM on R's features"
    input:
        lib=dtwin_sources("scripts/nominal_regimes.py"),
        residuals=rules.residuals.output.residuals,
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        states="results/regimes/nominal_states.csv",
        model="results/regimes/nominal_model.json",
        crosscheck="results/regimes/crosscheck.json",
    params:
        hmm=config["hmm"],
    log:
        "logs/nominal_regimes.log",
    benchmark:
        "benchmarks/rules/nominal_regimes.tsv"
    priority: PRIORITY_TWIN
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/nominal_regimes.py"


rule fig04_hmm_posteriors:
    message:
        "Drawing paper Fig. 4 (state posteriors) with the EM crosscheck on R's features"
    input:
        lib=dtwin_sources("scripts/fig04_hmm_posteriors.py"),
        states=rules.nominal_regimes.output.states,
        model=rules.nominal_regimes.output.model,
        crosscheck=rules.nominal_regimes.output.crosscheck,
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        png=report(
            "paper_figures/fig04_hmm_posteriors.png",
            caption="../report/fig04_hmm_posteriors.rst",
            category="§4.2 Regime inference",
        ),
        pdf="paper_figures/fig04_hmm_posteriors.pdf",
        json="paper_figures/fig04_hmm_posteriors.json",
    log:
        "logs/fig04_hmm_posteriors.log",
    benchmark:
        "benchmarks/rules/fig04_hmm_posteriors.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig04_hmm_posteriors.py"


#: Inputs of each data set's BIC sweep: its features and its dedicated K-state fit.
BIC_INPUTS = {
    "nominal_residuals": {
        "features": rules.residuals.output.residuals,
        "model": rules.nominal_regimes.output.model,
    },
    "fault_features": {
        "features": rules.fault_regimes.output.residuals,
        "model": rules.fault_regimes.output.summary,
    },
}


rule bic_sweep_dataset:
    message:
        "Sweeping K = {params.bic[ks]} and on until the BIC rose {params.bic[stop_after_rises]} "
        "times in a row (K <= {params.bic[k_max]}; {params.bic[n_restarts]} EM starts each) on "
        "the {wildcards.dataset}"
    input:
        lib=dtwin_sources("scripts/bic_sweep_dataset.py"),
        features=lambda wildcards: BIC_INPUTS[wildcards.dataset]["features"],
        model=lambda wildcards: BIC_INPUTS[wildcards.dataset]["model"],
    output:
        table="results/bic/{dataset}.csv",
    wildcard_constraints:
        dataset="|".join(BIC_INPUTS),
    params:
        bic=config["bic"],
        hmm={k: config["hmm"][k] for k in ("seed", "max_iter", "tol", "var_floor", "engine")},
    log:
        "logs/bic_sweep_dataset/{dataset}.log",
    benchmark:
        "benchmarks/rules/bic_sweep_dataset/{dataset}.tsv"
    priority: bic_sweep_priority
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/bic_sweep_dataset.py"


rule bic_sweep:
    message:
        "Joining the BIC sweeps of the nominal residuals and the fault features"
    input:
        lib=dtwin_sources("scripts/bic_sweep.py"),
        tables=expand("results/bic/{dataset}.csv", dataset=BIC_INPUTS),
    output:
        table="results/bic_sweep.csv",
    log:
        "logs/bic_sweep.log",
    benchmark:
        "benchmarks/rules/bic_sweep.tsv"
    priority: PRIORITY_CRITICAL_PATH
    threads: 1
    resources:
        mem_mb=500,
        runtime=2,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/bic_sweep.py"


rule bic_r_signals:
    message:
        "Sweeping K on R's own seed-11 {wildcards.dataset}, as Fig. 9 on ours: is K* = 8 the "
        "draw or the optimiser?"
    input:
        lib=dtwin_sources("scripts/bic_r_signals.py"),
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
    output:
        table="results/bic/r_signals/{dataset}.csv",
    wildcard_constraints:
        dataset="|".join(BIC_INPUTS),
    params:
        bic=config["bic"],
        hmm={k: config["hmm"][k] for k in ("seed", "max_iter", "tol", "var_floor", "engine")},
        twin={k: config["twin"][k] for k in ("dt", "fusion", "kpi")},
    log:
        "logs/bic_r_signals/{dataset}.log",
    benchmark:
        "benchmarks/rules/bic_r_signals/{dataset}.tsv"
    priority: bic_sweep_priority
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/bic_r_signals.py"


rule fig09_bic:
    message:
        "Drawing paper Fig. 9 (BIC against K) beside R's two BIC experiments"
    input:
        lib=dtwin_sources("scripts/fig09_bic.py"),
        table=rules.bic_sweep.output.table,
        r_signals=expand("results/bic/r_signals/{dataset}.csv", dataset=BIC_INPUTS),
        r_nominal=f"{REFERENCE_DIR}/bic_vs_K_6ch_nofault_singlefit_rerun.csv",
        r_features=f"{REFERENCE_DIR}/bic_vs_K_10feat_faulted_multistart5.csv",
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        png=report(
            "paper_figures/fig09_bic.png",
            caption="../report/fig09_bic.rst",
            category="§5 Model order",
        ),
        pdf="paper_figures/fig09_bic.pdf",
        json="paper_figures/fig09_bic.json",
    params:
        bic=config["bic"],
    log:
        "logs/fig09_bic.log",
    benchmark:
        "benchmarks/rules/fig09_bic.tsv"
    priority: PRIORITY_CRITICAL_PATH
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig09_bic.py"
