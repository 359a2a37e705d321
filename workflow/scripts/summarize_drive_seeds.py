"""Snakemake glue of the summarize_drive_seeds rule; the logic is topoloc.experiments.drive_seeds.summarize."""

from topoloc.experiments.drive_seeds import summarize
from topoloc.stage import run_stage

run_stage(snakemake, summarize)  # noqa: F821 (snakemake is injected by the script directive)
