"""Snakemake glue of the extract_odometry stage; the logic is topoloc.odometry.extract_odometry.run."""

from topoloc.odometry.extract_odometry import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
