"""Rule claims: paper_figures/CLAIMS.md and claims.json from every artifact's JSON.

Input   paper_figures/<artifact>.json for every artifact (paper and project; Fig. 12 adds the
        column "holds in k of N draws"), results/gap/benchmark.csv (cases behind each gap target)
Output  paper_figures/CLAIMS.md (the paper's claims, the project's targets, crosschecks,
        validity checks), paper_figures/claims.json
Params  project (the project's own artifacts), interval (level of the Wilson intervals)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

import pandas as pd

from dtwin.artifacts import atomic_write, write_json
from dtwin.claims import claims_markdown, summarise_claims

summary = summarise_claims(
    [json.loads(Path(p).read_text()) for p in snakemake.input.artifacts],
    project=snakemake.params.project,
    gap_table=pd.read_csv(snakemake.input.gap_table),
    level=snakemake.params.interval,
)
write_json(summary.to_json(), snakemake.output.json)
atomic_write(snakemake.output.markdown, lambda tmp: Path(tmp).write_text(claims_markdown(summary)))
