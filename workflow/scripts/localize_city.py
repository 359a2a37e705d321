"""Snakemake glue of the localize_city rule; the logic is topoloc.experiments.city.run."""

from topoloc.experiments.city import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
