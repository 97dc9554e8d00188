"""One module per paper stage: the computations behind the rules, over config sections.

A stage function takes tables and the config *sections* a rule passes as ``params:`` (plain
mappings, never the config file or the ``snakemake`` object).
"""
