"""Snakemake glue of the train_retrieval stage; the logic is topoloc.place.train_retrieval.run."""

from topoloc.place.train_retrieval import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
