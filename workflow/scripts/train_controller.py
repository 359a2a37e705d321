"""Snakemake glue of the train_controller stage; the logic is topoloc.drive.train_controller.run."""

from topoloc.drive.train_controller import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
