"""Snakemake glue of the build_graph stage; the logic is topoloc.graph.build_graph.run."""

from topoloc.graph.build_graph import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
