"""Snakemake glue of the follow_route stage; the logic is topoloc.drive.follow_route.run."""

from topoloc.drive.follow_route import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
