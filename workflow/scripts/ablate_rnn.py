"""Snakemake glue of the ablate_rnn rule; the logic is topoloc.experiments.rnn_ablation.run."""

from topoloc.experiments.rnn_ablation import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
