"""Snakemake glue of the evaluate_rnn stage; the logic is topoloc.trajectory.evaluate_rnn.run."""

from topoloc.stage import run_stage
from topoloc.trajectory.evaluate_rnn import run

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
