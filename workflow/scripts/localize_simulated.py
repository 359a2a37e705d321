"""Snakemake glue of the localize_simulated rule; the logic is topoloc.experiments.simulated.run."""

from topoloc.experiments.simulated import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
