"""Snakemake glue of the summarize_rnn_ablation rule; the logic is topoloc.experiments.rnn_ablation.summarize."""

from topoloc.experiments.rnn_ablation import summarize
from topoloc.stage import run_stage

run_stage(snakemake, summarize)  # noqa: F821 (snakemake is injected by the script directive)
