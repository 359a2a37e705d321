"""Snakemake glue of the summarize_regions stage; the logic is topoloc.localization.summarize_regions.run."""

from topoloc.localization.summarize_regions import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
