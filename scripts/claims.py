"""Rule claims: paper_figures/CLAIMS.md and claims.json from every artifact's JSON.

Input   paper_figures/<artifact>.json for every paper artifact
Output  paper_figures/CLAIMS.md (claims, crosschecks, validity checks), paper_figures/claims.json
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

from dtwin.artifacts import atomic_write, write_json
from dtwin.claims import claims_markdown, summarise_claims

summary = summarise_claims([json.loads(Path(p).read_text()) for p in snakemake.input.artifacts])
write_json(summary.to_json(), snakemake.output.json)
atomic_write(snakemake.output.markdown, lambda tmp: Path(tmp).write_text(claims_markdown(summary)))
