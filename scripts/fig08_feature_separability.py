"""Rule fig08_feature_separability: paper Fig. 8, the ten z-scored features by regime.

Input   results/faults/residuals.csv   t, regime, e0..e4 (the features are derived from them)
Output  paper_figures/fig08_feature_separability.{png,pdf,json}
"""

from dtwin._script import start_rule

start_rule(snakemake)

import pandas as pd

from dtwin.figures._style import publish_artifact
from dtwin.figures.fig08_feature_separability import fig08_feature_separability

artifact = fig08_feature_separability(pd.read_csv(snakemake.input.residuals))
publish_artifact(artifact, [snakemake.output.png, snakemake.output.pdf], snakemake.output.json)
