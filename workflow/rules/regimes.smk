"""Stage "regimes" (paper §4.2, §5): nominal_regimes → Fig. 4; bic_sweep → Fig. 9.

bic_sweep also reads the fault scenario's residuals, so faults.smk is included first.
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


rule bic_sweep:
    message:
        "Sweeping K = {params.bic[ks]} and on until the BIC rose {params.bic[stop_after_rises]} "
        "times in a row (K <= {params.bic[k_max]}; {params.bic[n_restarts]} EM starts each) on "
        "the nominal residuals and the fault features"
    input:
        lib=dtwin_sources("scripts/bic_sweep.py"),
        residuals=rules.residuals.output.residuals,
        fault_residuals=rules.fault_regimes.output.residuals,
        nominal_model=rules.nominal_regimes.output.model,
        fault_summary=rules.fault_regimes.output.summary,
    output:
        table="results/bic_sweep.csv",
    params:
        bic=config["bic"],
        hmm={k: config["hmm"][k] for k in ("seed", "max_iter", "tol", "var_floor")},
    log:
        "logs/bic_sweep.log",
    benchmark:
        "benchmarks/rules/bic_sweep.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/bic_sweep.py"


rule fig09_bic:
    message:
        "Drawing paper Fig. 9 (BIC against K) beside R's two BIC experiments"
    input:
        lib=dtwin_sources("scripts/fig09_bic.py"),
        table=rules.bic_sweep.output.table,
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
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig09_bic.py"
