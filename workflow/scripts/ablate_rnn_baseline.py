"""Snakemake glue of the ablate_rnn_baseline rule; the logic is topoloc.experiments.rnn_ablation.baseline."""

from topoloc.experiments.rnn_ablation import baseline
from topoloc.stage import run_stage

run_stage(snakemake, baseline)  # noqa: F821 (snakemake is injected by the script directive)
