"""Snakemake glue of the train_rnn stage; the logic is topoloc.trajectory.train_rnn.run."""

from topoloc.stage import run_stage
from topoloc.trajectory.train_rnn import run

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
