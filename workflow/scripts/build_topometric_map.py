"""Snakemake glue of the build_topometric_map stage; the logic is topoloc.place.build_topometric_map.run."""

from topoloc.place.build_topometric_map import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
