"""gap_cases: generate one chunk of the benchmark's withheld-effect recordings.

Inputs: none (each case name ``<effect>_<NN>`` picks the effect and the seed; ``rig_<effect>``
cases come from the rig family, docs/gap.md §Rig family).
Outputs: ``folder`` = results/gap/cases/{scatteritem}/ with one sub-folder per case of the chunk:
``recording.csv`` (t in s, signals in the twin's units), ``twin.yaml`` (the nominal twin, noise
levels right to ±10 %), ``key.json`` (the truth; the diagnoser never reads it).
Params: ``cases`` (this chunk's case names), ``benchmark`` = config ``gap.benchmark``
(``effects``, ``first_seed``, ``miscalibration``, ``noise_error``), ``twin`` = config ``twin``
(the nominal twin of every paper-asset case).
"""

from dtwin._script import start_rule

start_rule(snakemake)


from pathlib import Path

from dtwin.gapbench.batch import write_case_folder

for case in snakemake.params.cases:
    write_case_folder(
        case,
        snakemake.params.benchmark,
        snakemake.params.twin,
        Path(snakemake.output.folder) / case,
    )
