"""Snakemake glue of the view_drive stage; the logic is topoloc.viewer.view_drive.run."""

from topoloc.viewer.view_drive import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
