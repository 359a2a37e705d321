"""Snakemake glue of the localize_map_errors rule; the logic is topoloc.experiments.map_errors.run."""

from topoloc.experiments.map_errors import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
