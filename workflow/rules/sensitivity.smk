"""Stage "sensitivity" (paper §5, Fig. 11): the grid in chunks of points, one figure.

The grid and the replicates come from config["sensitivity"]; sweep_chunk runs one chunk of
points per job (Snakemake scattergather "sweep": `--set-scatter sweep=N`, see common.smk) and
fig11_sensitivity gathers them. Chunks are independent (no shared inputs but the config and
R's reference signals), so a cluster executor can spread them out.
"""


rule sweep_chunk:
    message:
        "Sensitivity sweep: grid points of chunk {wildcards.scatteritem}, one after another"
    input:
        lib=dtwin_sources("scripts/sweep_chunk.py"),
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
    output:
        json="results/sensitivity/chunks/{scatteritem}.json",
    params:
        points=points_of_chunk,
        simulation=config["simulation"],
        command=config["command"],
        twin=config["twin"],
        arx=config["arx"],
        sensitivity=SENSITIVITY_JOB_PARAMS,
    log:
        "logs/sweep_chunk/{scatteritem}.log",
    benchmark:
        "benchmarks/rules/sweep_chunk/{scatteritem}.tsv"
    threads: 1
    priority: PRIORITY_SWEEP
    resources:
        mem_mb=500,
        runtime=sweep_chunk_runtime,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/sweep_chunk.py"


rule fig11_sensitivity:
    message:
        "Drawing paper Fig. 11 from {params.n_runs} sweep runs, beside R's re-run"
    input:
        lib=dtwin_sources("scripts/fig11_sensitivity.py"),
        runs=sweep_chunk_files(),
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
        n_runs=len(SWEEP_POINTS),
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
