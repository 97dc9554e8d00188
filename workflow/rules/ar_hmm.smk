"""Stage "ar_hmm" (paper §5, future work): the AR(1)-emission HMM on the fault features → Fig. 13.

ar_hmm_sweep fits the switching AR(1) HMM for every K of a BIC sweep (config["ar_hmm"]) to
the fault features of Fig. 7; fig13_ar_hmm sets its BIC minimum and Hungarian accuracy beside
the Gaussian HMM's (bic_sweep, fault_regimes). Included after regimes.smk.
"""


rule ar_hmm_sweep:
    message:
        "AR(1)-emission HMM: BIC over K = {params.ar_hmm[ks]} and on until it rose "
        "{params.ar_hmm[stop_after_rises]} times (K <= {params.ar_hmm[k_max]}; "
        "{params.ar_hmm[n_restarts]} EM starts each) on the fault features"
    input:
        lib=dtwin_sources("scripts/ar_hmm_sweep.py"),
        residuals=rules.fault_regimes.output.residuals,
    output:
        table="results/ar_hmm/bic.csv",
        summary="results/ar_hmm/summary.json",
    params:
        ar_hmm={**config["ar_hmm"], "engine": config["hmm"]["engine"]},
        n_states=config["hmm"]["n_states"],
    log:
        "logs/ar_hmm_sweep.log",
    benchmark:
        "benchmarks/rules/ar_hmm_sweep.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/ar_hmm_sweep.py"


rule fig13_ar_hmm:
    message:
        "Drawing Fig. 13: the AR(1)-emission HMM beside the Gaussian HMM (BIC over K, accuracy)"
    input:
        lib=dtwin_sources("scripts/fig13_ar_hmm.py"),
        ar_table=rules.ar_hmm_sweep.output.table,
        ar_summary=rules.ar_hmm_sweep.output.summary,
        gaussian_table=rules.bic_sweep.output.table,
        fault_summary=rules.fault_regimes.output.summary,
    output:
        png=report(
            "paper_figures/fig13_ar_hmm.png",
            caption="../report/fig13_ar_hmm.rst",
            category="§5 Model order",
        ),
        pdf="paper_figures/fig13_ar_hmm.pdf",
        json="paper_figures/fig13_ar_hmm.json",
    params:
        n_states=config["hmm"]["n_states"],
    log:
        "logs/fig13_ar_hmm.log",
    benchmark:
        "benchmarks/rules/fig13_ar_hmm.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig13_ar_hmm.py"
