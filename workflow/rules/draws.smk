"""Stage "draws": the paper's single-draw claims on N random draws → Fig. 12.

claims_draws runs one chunk of draws (config["draws"]["chunk_size"] per job; the chunk list
is draw_chunk_files() in common.smk); fig12_claims_across_draws gathers them. Draw 0 is the
main run, so the claims rule can check that its verdicts equal the figures'. bic_draws sweeps
the BIC over K on the first draws.bic.n_draws draws (K* across draws, Fig. 9's claims) with
draws.bic.n_restarts EM starts per K, in chunks of draws.bic.chunk_size.
"""


rule claims_draws:
    message:
        "Claims across draws: rerunning the single-draw pipeline for draws {params.draws}"
    input:
        lib=dtwin_sources("scripts/claims_draws.py"),
        r_summary=f"{REFERENCE_DIR}/classification_summary_K4.csv",
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        json="results/draws/chunk{chunk}.json",
    params:
        draws=draws_of_chunk,
        sections=DRAW_SECTIONS,
        acf=DRAW_ACF,
    log:
        "logs/claims_draws/chunk{chunk}.log",
    benchmark:
        "benchmarks/rules/claims_draws/chunk{chunk}.tsv"
    priority: PRIORITY_DRAWS
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/claims_draws.py"


rule bic_draws:
    message:
        "K* across draws: the BIC over K ({params.bic[n_restarts]} EM starts each) on draws "
        "{params.draws}"
    input:
        lib=dtwin_sources("scripts/bic_draws.py"),
    output:
        json="results/draws/bic/chunk{chunk}.json",
    params:
        draws=bic_draws_of_chunk,
        sections=DRAW_REGIME_SECTIONS,
        bic=DRAW_BIC,
    log:
        "logs/bic_draws/chunk{chunk}.log",
    benchmark:
        "benchmarks/rules/bic_draws/chunk{chunk}.tsv"
    priority: PRIORITY_DRAWS
    threads: 1
    resources:
        mem_mb=500,
        runtime=20,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/bic_draws.py"


rule fig12_claims_across_draws:
    message:
        "Drawing Fig. 12: the paper's claims across {params.draws[n_draws]} random draws"
    input:
        lib=dtwin_sources("scripts/fig12_claims_across_draws.py"),
        chunks=draw_chunk_files(config["draws"]),
        bic_chunks=bic_draw_chunk_files(config["draws"]),
        bic_main=rules.bic_sweep.output.table,
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_metrics=f"{REFERENCE_DIR}/targeted_intervention_metrics_rerun.csv",
        r_summary=f"{REFERENCE_DIR}/classification_summary_K4.csv",
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        png=report(
            "paper_figures/fig12_claims_across_draws.png",
            caption="../report/fig12_claims_across_draws.rst",
            category="Claims across draws",
        ),
        pdf="paper_figures/fig12_claims_across_draws.pdf",
        json="paper_figures/fig12_claims_across_draws.json",
        table="results/draws/draws.csv",
        k_star="results/draws/k_star.csv",
    params:
        draws=config["draws"],
        bic_draws=bic_draw_count(config["draws"]),
        main_n_restarts=config["bic"]["n_restarts"],
    log:
        "logs/fig12_claims_across_draws.log",
    benchmark:
        "benchmarks/rules/fig12_claims_across_draws.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig12_claims_across_draws.py"
