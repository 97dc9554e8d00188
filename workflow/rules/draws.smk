"""Stage "draws" (issue 12): the paper's single-draw claims on N random draws → Fig. 12.

claims_draws runs one chunk of draws (config["draws"]["chunk_size"] per job; the chunk list
is draw_chunk_files() in common.smk); fig12_claims_across_draws gathers them. Draw 0 is the
main run, so the claims rule can check that its verdicts equal the figures'.
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
    threads: 1
    resources:
        mem_mb=500,
        runtime=10,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/claims_draws.py"


rule fig12_claims_across_draws:
    message:
        "Drawing Fig. 12: the paper's claims across {params.draws[n_draws]} random draws"
    input:
        lib=dtwin_sources("scripts/fig12_claims_across_draws.py"),
        chunks=draw_chunk_files(config["draws"]),
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
    params:
        draws=config["draws"],
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
