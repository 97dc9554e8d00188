"""Rule bic_draws: the BIC over K (Fig. 9) on one chunk of random draws, for K* across draws.

Input   (the library only: every draw is rerun from the config)
Output  results/draws/bic/chunk<c>.json   {"draws": [{draw, seeds, bic: [rows of
                                          results/bic_sweep.csv's columns]}]}
Params  draws (the chunk's draw numbers), sections (simulation, command, twin, arx, faults,
        hmm: the draw up to its fault HMM, no correction or mcda), bic (ks, k_max,
        stop_after_rises; n_restarts of draws.bic)
"""

from dtwin._script import start_rule

start_rule(snakemake)

from dtwin.artifacts import write_json
from dtwin.stages.draws import run_draw_bic

params = snakemake.params
records = [run_draw_bic(draw, params.sections, params.bic) for draw in params.draws]
write_json({"draws": records}, snakemake.output.json)
