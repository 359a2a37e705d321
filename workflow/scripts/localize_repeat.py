"""Snakemake glue of the localize_repeat stage; the logic is topoloc.place.localize_repeat.run."""

from topoloc.place.localize_repeat import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
