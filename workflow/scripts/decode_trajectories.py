"""Snakemake glue of the decode_trajectories stage; the logic is topoloc.localization.decode_trajectories.run."""

from topoloc.localization.decode_trajectories import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
