"""Snakemake glue of the render_places stage; the logic is topoloc.place.render_places.run."""

from topoloc.place.render_places import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
