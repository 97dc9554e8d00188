"""gap_diagnoses: diagnose one chunk of recordings' sim-to-real gaps, as `dtwin diagnose` does.

Inputs: ``cases`` = results/gap/cases/{scatteritem}/ (per case: ``recording.csv``, t in s and
module signals, and ``twin.yaml``; ``key.json`` stays unread).
Outputs: ``folder`` = results/gap/diagnoses/{scatteritem}/ with one sub-folder per case:
``diagnosis.json`` (schema workflow/schemas/diagnosis.schema.json) and ``report.md`` (no
``gap.png``: the benchmark reads the JSON; `dtwin diagnose` on a case folder draws it).
Params: ``cases`` (this chunk's case names), ``diagnose`` = config ``gap.diagnose``
(``train_frac``, ``calibrate`` and the decision constants of
:class:`dtwin.gap.results.GapSettings`).
"""

from dtwin._script import start_rule

start_rule(snakemake)


from pathlib import Path

from dtwin.gapbench.batch import diagnose_case_folder

for case in snakemake.params.cases:
    diagnose_case_folder(
        Path(snakemake.input.cases) / case,
        snakemake.params.diagnose,
        Path(snakemake.output.folder) / case,
    )
