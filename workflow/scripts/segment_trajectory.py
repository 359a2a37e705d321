"""Snakemake glue of the segment_trajectory stage; the logic is topoloc.odometry.segment_trajectory.run."""

from topoloc.odometry.segment_trajectory import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
