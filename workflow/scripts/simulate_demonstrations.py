"""Snakemake glue of the simulate_demonstrations stage; the logic is topoloc.drive.simulate_demonstrations.run."""

from topoloc.drive.simulate_demonstrations import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
