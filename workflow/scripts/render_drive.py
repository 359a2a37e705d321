"""Snakemake glue of the render_drive stage; the logic is topoloc.render.render_drive.run."""

from topoloc.render.render_drive import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
