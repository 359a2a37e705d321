"""Snakemake glue of the view_repeat stage; the logic is topoloc.viewer.view_repeat.run."""

from topoloc.viewer.view_repeat import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
