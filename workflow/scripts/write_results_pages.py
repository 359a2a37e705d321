"""Snakemake glue of the write_results_pages stage; the logic is topoloc.report.write_results_pages.run."""

from topoloc.report.write_results_pages import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
