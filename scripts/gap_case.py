"""gap_case: generate one recording with a withheld effect.

Inputs: none (the case name ``{case}`` = ``<effect>_<NN>`` picks the effect and the seed;
``rig_<effect>`` cases come from the rig family, docs/gap.md §Rig family).
Outputs: ``recording.csv`` (t in s, signals in the twin's units), ``twin.yaml`` (the nominal twin,
noise levels right to ±10 %), ``key.json`` (the truth; the diagnoser never reads it).
Config: ``gap.benchmark`` (``effects``, ``first_seed``, ``miscalibration``, ``noise_error``).
"""

from dtwin._script import start_rule

start_rule(snakemake)


from pathlib import Path

import yaml

from dtwin.artifacts import atomic_write, write_csv, write_json
from dtwin.gap.generator import case_spec
from dtwin.gap.rigs import generate_any_case

settings = snakemake.params.benchmark
spec = case_spec(snakemake.wildcards.case, settings["effects"], settings["first_seed"])
case = generate_any_case(
    spec["effect"],
    spec["seed"],
    miscalibration=settings["miscalibration"],
    noise_error=settings["noise_error"],
)
write_csv(case.recording, snakemake.output.recording)
twin_text = yaml.safe_dump(case.twin, sort_keys=False)
atomic_write(snakemake.output.twin, lambda tmp: Path(tmp).write_text(twin_text))
write_json({"case": snakemake.wildcards.case, **case.key}, snakemake.output.key)
