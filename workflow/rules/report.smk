"""Stage "report": one page of truth gathered from every artifact's checks."""


rule claims:
    message:
        "Gathering every artifact's claims, crosschecks and validity checks into CLAIMS.md and the report's contact sheet"
    input:
        lib=dtwin_sources("scripts/claims.py"),
        artifacts=[f"paper_figures/{a}.json" for a in (*PAPER_ARTIFACTS, *ARTIFACTS["project"])],
        pngs=[f"paper_figures/{a}.png" for a in (*PAPER_ARTIFACTS, *ARTIFACTS["project"])],
    output:
        markdown="paper_figures/CLAIMS.md",
        json="paper_figures/claims.json",
        sheet="paper_figures/contact_sheet.html",
    params:
        project=ARTIFACTS["project"],
        interval=config["draws"]["interval"],
    log:
        "logs/claims.log",
    benchmark:
        "benchmarks/rules/claims.tsv"
    threads: 1
    resources:
        mem_mb=300,
        runtime=2,
    conda:
        "../envs/dtwin.yaml"
    script:
        "../../scripts/claims.py"
