"""Snakemake glue of the check_controller_seed rule; the logic is topoloc.experiments.drive_seeds.run."""

from topoloc.experiments.drive_seeds import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
