"""dtwin: reproduce "Hidden Markov Inference Framework for Error Propagation Mitigation in
Modular Digital Twins" as a DAG. `snakemake --cores 2` regenerates every figure into
paper_figures/. Rules live in workflow/rules/, one file per paper stage."""

from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"  # the landing page of `make report`: the contact sheet


include: "workflow/rules/common.smk"
include: "workflow/rules/twin.smk"
include: "workflow/rules/faults.smk"  # before regimes.smk: bic_sweep reads the fault residuals
include: "workflow/rules/regimes.smk"
include: "workflow/rules/ar_hmm.smk"  # after regimes.smk: fig13 reads the BIC sweep
include: "workflow/rules/correction.smk"
include: "workflow/rules/decisions.smk"
include: "workflow/rules/sensitivity.smk"
include: "workflow/rules/gap.smk"
include: "workflow/rules/draws.smk"
include: "workflow/rules/report.smk"


rule all:
    default_target: True
    input:
        ALL_TARGETS,
