"""Snakemake glue of the download_osm stage; the logic is topoloc.osm.download_osm.run."""

from topoloc.osm.download_osm import run
from topoloc.stage import run_stage

run_stage(snakemake, run)  # noqa: F821 (snakemake is injected by the script directive)
