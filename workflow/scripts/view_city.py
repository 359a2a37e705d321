"""Snakemake glue of the view_city stage; the logic is topoloc.viewer.view_city.run."""

from topoloc.viewer.view_city import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
