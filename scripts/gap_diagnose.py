"""gap_diagnose: diagnose one recording's sim-to-real gap, as `dtwin diagnose` does.

Inputs: ``recording`` (CSV: t in s and module signals), ``twin`` (YAML twin file).
Outputs: ``diagnosis.json`` (schema workflow/schemas/diagnosis.schema.json), ``report.md``,
``gap.png`` — all in one folder, each written atomically.
Config: ``gap.diagnose`` (``train_frac``, ``calibrate`` and the decision constants of
:class:`dtwin.gap.diagnose.GapSettings`).
"""

from dtwin._script import start_rule

start_rule(snakemake)


from pathlib import Path

import yaml

from dtwin.gap import (
    GapSettings,
    diagnose,
    read_recording,
    twin_discretisation,
    twin_from_mapping,
    write_report,
)

settings = dict(snakemake.params.diagnose)
train_frac = settings.pop("train_frac")
calibrate = bool(settings.pop("calibrate"))
recording = read_recording(snakemake.input.recording)
twin_content = yaml.safe_load(Path(snakemake.input.twin).read_text())
twin = twin_from_mapping(twin_content, dt=recording.dt)
result = diagnose(
    recording,
    twin,
    calibrate=calibrate,
    train_frac=train_frac,
    settings=GapSettings.from_mapping(settings),
    discretisation=twin_discretisation(twin_content),
)
write_report(result, Path(snakemake.output.diagnosis).parent)
