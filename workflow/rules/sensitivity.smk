"""Stage "sensitivity" (paper §5, Fig. 11): one job per (alpha, m_A, m_B, replicate), one figure.

The grid and the replicates come from config["sensitivity"]; the target list is built by
sensitivity_run_files() in common.smk. Jobs are independent (no shared inputs but the config
and R's reference signals), so a cluster executor can spread them out.
"""


rule sweep_point:
    message:
        "Sensitivity sweep: alpha {wildcards.alpha}, m_A {wildcards.ma}, m_B {wildcards.mb}, "
        "replicate {wildcards.rep}"
    input:
        lib=dtwin_sources("scripts/sweep_point.py"),
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
    output:
        json=f"results/sensitivity/{SWEEP_POINT}.json",
    params:
        point=sweep_point_of,
        simulation=config["simulation"],
        command=config["command"],
        twin=config["twin"],
        arx=config["arx"],
        sensitivity=SENSITIVITY_JOB_PARAMS,
    log:
        f"logs/sweep_point/{SWEEP_POINT}.log",
    benchmark:
        f"benchmarks/rules/sweep_point/{SWEEP_POINT}.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/sweep_point.py"


rule fig11_sensitivity:
    message:
        "Drawing paper Fig. 11 from {params.n_runs} sweep runs, beside R's re-run"
    input:
        lib=dtwin_sources("scripts/fig11_sensitivity.py"),
        runs=sensitivity_run_files(config["sensitivity"]),
        r_sweep=f"{REFERENCE_DIR}/sensitivity_36_rerun.csv",
    output:
        png=report(
            "paper_figures/fig11_sensitivity.png",
            caption="../report/fig11_sensitivity.rst",
            category="§5 Robustness",
        ),
        pdf="paper_figures/fig11_sensitivity.pdf",
        json="paper_figures/fig11_sensitivity.json",
        summary="results/sensitivity/summary.csv",
        runs="results/sensitivity/runs.csv",
    params:
        sensitivity=config["sensitivity"],
        n_runs=len(sensitivity_run_files(config["sensitivity"])),
    log:
        "logs/fig11_sensitivity.log",
    benchmark:
        "benchmarks/rules/fig11_sensitivity.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig11_sensitivity.py"
