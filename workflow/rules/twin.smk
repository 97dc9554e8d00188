"""Stage "twin" (paper §3, §4.1): simulate → fit_surrogates → residuals → Figs. 1–3."""


rule simulate:
    message:
        "Simulating the physical asset ({params.simulation[T]} s, seed {params.simulation[seed]})"
    input:
        lib=dtwin_sources("scripts/simulate.py"),
    output:
        physics="results/physics.csv",
    params:
        simulation=config["simulation"],
        command=config["command"],
        twin=config["twin"],
    log:
        "logs/simulate.log",
    benchmark:
        "benchmarks/rules/simulate.tsv"
    priority: PRIORITY_TWIN
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/simulate.py"


rule fit_surrogates:
    message:
        "Fitting the ARX surrogates on the first {params.arx[train_frac]} of the run and "
        "crosschecking the fit and rollout on R's signals"
    input:
        lib=dtwin_sources("scripts/fit_surrogates.py"),
        physics=rules.simulate.output.physics,
        r_pipeline=f"{REFERENCE_DIR}/faulted_pipeline_seed11_rerun.csv",
        r_theta=f"{REFERENCE_DIR}/arx_theta_seed11_rerun.csv",
    output:
        theta="results/arx_theta.csv",
        crosscheck="results/arx_crosscheck.json",
    params:
        arx={k: config["arx"][k] for k in ("orders", "train_frac")},
        twin=config["twin"],
    log:
        "logs/fit_surrogates.log",
    benchmark:
        "benchmarks/rules/fit_surrogates.tsv"
    priority: PRIORITY_TWIN
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fit_surrogates.py"


rule residuals:
    message:
        "Rolling out the surrogate chain and computing module residuals"
    input:
        lib=dtwin_sources("scripts/residuals.py"),
        physics=rules.simulate.output.physics,
        theta=rules.fit_surrogates.output.theta,
    output:
        surrogate="results/surrogate.csv",
        residuals="results/residuals.csv",
    params:
        twin=config["twin"],
        rollout_init=config["arx"]["rollout_init"],
    log:
        "logs/residuals.log",
    benchmark:
        "benchmarks/rules/residuals.tsv"
    priority: PRIORITY_TWIN
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/residuals.py"


rule fig01_pipeline:
    message:
        "Drawing paper Fig. 1 from the wiring table"
    input:
        lib=dtwin_sources("scripts/fig01_pipeline.py"),
    output:
        png=report(
            "paper_figures/fig01_pipeline.png",
            caption="../report/fig01_pipeline.rst",
            category="§3 The modular twin",
        ),
        pdf="paper_figures/fig01_pipeline.pdf",
        json="paper_figures/fig01_pipeline.json",
    params:
        arx={"orders": config["arx"]["orders"]},
    log:
        "logs/fig01_pipeline.log",
    benchmark:
        "benchmarks/rules/fig01_pipeline.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig01_pipeline.py"


rule fig02_arx_vs_physics:
    message:
        "Drawing paper Fig. 2 (physics vs ARX) with the ARX crosschecks against R"
    input:
        lib=dtwin_sources("scripts/fig02_arx_vs_physics.py"),
        physics=rules.simulate.output.physics,
        surrogate=rules.residuals.output.surrogate,
        residuals=rules.residuals.output.residuals,
        theta=rules.fit_surrogates.output.theta,
        crosscheck=rules.fit_surrogates.output.crosscheck,
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        png=report(
            "paper_figures/fig02_arx_vs_physics.png",
            caption="../report/fig02_arx_vs_physics.rst",
            category="§4.1 Surrogates and structured residuals",
        ),
        pdf="paper_figures/fig02_arx_vs_physics.pdf",
        json="paper_figures/fig02_arx_vs_physics.json",
    params:
        arx=config["arx"],
    log:
        "logs/fig02_arx_vs_physics.log",
    benchmark:
        "benchmarks/rules/fig02_arx_vs_physics.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig02_arx_vs_physics.py"


rule fig03_residual_acf:
    message:
        "Drawing paper Fig. 3 (residual ACF) with Ljung-Box tests"
    input:
        lib=dtwin_sources("scripts/fig03_residual_acf.py"),
        residuals=rules.residuals.output.residuals,
        r_numbers=f"{REFERENCE_DIR}/r_numbers.yaml",
    output:
        png=report(
            "paper_figures/fig03_residual_acf.png",
            caption="../report/fig03_residual_acf.rst",
            category="§4.1 Surrogates and structured residuals",
        ),
        pdf="paper_figures/fig03_residual_acf.pdf",
        json="paper_figures/fig03_residual_acf.json",
    params:
        acf=config["acf"],
    log:
        "logs/fig03_residual_acf.log",
    benchmark:
        "benchmarks/rules/fig03_residual_acf.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/fig03_residual_acf.py"
