"""Snakemake glue of the generate_dataset stage; the logic is topoloc.trajectory.generate_dataset.run."""

from topoloc.stage import run_stage
from topoloc.trajectory.generate_dataset import run

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
