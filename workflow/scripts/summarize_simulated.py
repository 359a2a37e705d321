"""Snakemake glue of the summarize_simulated rule; the logic is topoloc.experiments.simulated.summarize."""

from topoloc.experiments.simulated import summarize
from topoloc.stage import run_stage

run_stage(snakemake, summarize)  # noqa: F821 (snakemake is injected by the script directive)
