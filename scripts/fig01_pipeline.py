"""Rule fig01_pipeline: paper Fig. 1, the six-module twin drawn from dtwin.twin.wiring.MODULES.

Output  paper_figures/fig01_pipeline.{png,pdf,json}
Params  arx (orders, for the box labels)
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.config_sections import ArxSettings
from dtwin.figures._style import publish_artifact
from dtwin.figures.fig01_pipeline import fig01_pipeline

artifact = fig01_pipeline(ArxSettings.from_mapping(snakemake.params.arx))
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
