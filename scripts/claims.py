"""Rule claims: paper_figures/CLAIMS.md and claims.json from every artifact's JSON.

Input   paper_figures/<artifact>.json and .png for every artifact (paper and project; Fig. 12
        adds the column "holds in k of N draws"; gap_benchmark's metrics give the cases behind
        each gap target)
Output  paper_figures/CLAIMS.md (the paper's claims, the project's targets, crosschecks,
        validity checks), paper_figures/claims.json, paper_figures/contact_sheet.html (the
        report's landing page: every figure as a thumbnail with its finding)
Params  project (the project's own artifacts), interval (level of the Wilson intervals)
"""

from dtwin._script import start_rule

start_rule(snakemake)

import json
from pathlib import Path

from dtwin.artifacts import atomic_write, write_json
from dtwin.claims import claims_markdown, summarise_claims
from dtwin.figures._contact_sheet import contact_sheet_html, thumbnail_png

payloads = [json.loads(Path(p).read_text()) for p in snakemake.input.artifacts]
summary = summarise_claims(
    payloads,
    project=snakemake.params.project,
    level=snakemake.params.interval,
)
write_json(summary.to_json(), snakemake.output.json)
atomic_write(snakemake.output.markdown, lambda tmp: Path(tmp).write_text(claims_markdown(summary)))
thumbnails = {Path(p).stem: thumbnail_png(Path(p).read_bytes()) for p in snakemake.input.pngs}
sheet = contact_sheet_html(payloads, thumbnails, summary.to_json())
atomic_write(snakemake.output.sheet, lambda tmp: Path(tmp).write_text(sheet, encoding="utf-8"))
