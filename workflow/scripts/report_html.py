"""Snakemake glue of the report_html rule: `snakemake --report` on this job's inputs, as a stage with its MLflow run.

A report can only be built by a separate `snakemake --report` call (it reads
the provenance records of finished jobs); this job makes that call with the
same Snakefile and config, for the files of `rule all` before the report, and
logs the HTML to MLflow like any stage output.
"""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from topoloc.errors import InputError
from topoloc.io import atomic_path, temporary_name
from topoloc.stage import run_stage
from topoloc.tracking import INVOCATION_ENV


def build_report(conf, inputs, outputs):
    out = Path(outputs["html"])
    targets = [str(path) for path in snakemake.input]  # noqa: F821 (unnamed: every file of rule all before the report)
    env = {k: v for k, v in os.environ.items() if k != INVOCATION_ENV}  # the nested call opens no MLflow runs
    with tempfile.NamedTemporaryFile("w", prefix=temporary_name(out), suffix=".yaml", dir=out.parent, delete=False) as handle:
        yaml.safe_dump(dict(snakemake.config), handle)  # noqa: F821 (the merged config of this call)
    try:
        with atomic_path(out) as tmp:
            cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(snakemake.params.snakefile),  # noqa: F821
                   "--configfile", handle.name, "--cores", "1", "--nolock", "--report", str(tmp), *targets]
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
            if proc.returncode != 0 or not tmp.exists() or tmp.stat().st_size == 0:
                raise InputError(out, f"snakemake --report failed: {(proc.stderr or proc.stdout).strip().splitlines()[-1:]}")
    finally:
        os.unlink(handle.name)
    return {"report_bytes": float(out.stat().st_size)}


run_stage(snakemake, build_report)  # noqa: F821 (snakemake is injected by the script directive)
