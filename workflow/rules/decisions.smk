"""Stage "decisions" (paper §5, Table 1): MCDA/TOPSIS action selection → Fig. 10."""


rule mcda_actions:
    message:
        "Selecting a mitigation action per step with TOPSIS (gate, dwell, margin) and "
        "crosschecking the legacy mode against R"
    input:
        lib=dtwin_sources("scripts/mcda_actions.py"),
        residuals="results/faults/residuals.csv",
        posteriors="results/faults/posteriors.csv",
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_timeline=f"{REFERENCE_DIR}/mcda_actions_timeline_rerun.csv",
    output:
        timeline="results/mcda/actions.csv",
        crosscheck="results/mcda/crosscheck.json",
    params:
        mcda=config["mcda"],
        dt=config["twin"]["dt"],
    log:
        "logs/mcda_actions.log",
    benchmark:
        "benchmarks/rules/mcda_actions.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/mcda_actions.py"


rule fig10_mcda_actions:
    message:
        "Drawing paper Fig. 10 (actions over the true regimes) with the crosscheck against R"
    input:
        lib=dtwin_sources("scripts/fig10_mcda_actions.py"),
        timeline=rules.mcda_actions.output.timeline,
        crosscheck=rules.mcda_actions.output.crosscheck,
        r_counts=f"{REFERENCE_DIR}/mcda_action_counts_rerun.csv",
    output:
        png=report(
            "paper_figures/fig10_mcda_actions.png",
            caption="../report/fig10_mcda_actions.rst",
            category="§5 Decisions and robustness",
        ),
        pdf="paper_figures/fig10_mcda_actions.pdf",
        json="paper_figures/fig10_mcda_actions.json",
    params:
        mcda=config["mcda"],
        dt=config["twin"]["dt"],
    log:
        "logs/fig10_mcda_actions.log",
    benchmark:
        "benchmarks/rules/fig10_mcda_actions.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig10_mcda_actions.py"
