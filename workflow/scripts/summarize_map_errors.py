"""Snakemake glue of the summarize_map_errors rule; the logic is topoloc.experiments.map_errors.summarize."""

from topoloc.experiments.map_errors import summarize
from topoloc.stage import run_stage

run_stage(snakemake, summarize)  # noqa: F821 (snakemake is injected by the script directive)
