"""Snakemake glue of the evaluate_localization stage; the logic is topoloc.localization.evaluate_localization.run."""

from topoloc.localization.evaluate_localization import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
