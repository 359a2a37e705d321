"""Snakemake glue of the summarize_city rule; the logic is topoloc.experiments.city.summarize."""

from topoloc.experiments.city import summarize
from topoloc.stage import run_stage

run_stage(snakemake, summarize)  # noqa: F821 (snakemake is injected by the script directive)
