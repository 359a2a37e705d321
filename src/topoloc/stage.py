"""Glue between a Snakemake job and a stage's ``run(conf, inputs, outputs)``.

Workflow scripts are two lines: import the stage and call :func:`run_stage`
with the ``snakemake`` object. This module never imports Snakemake; it reads
the job's attributes (``input``, ``output``, ``params``, ``log``, ``rule``,
``wildcards``, ``config``) by duck typing.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from topoloc.errors import InputError
from topoloc.hashing import sha256_file
from topoloc.tracking import StageRun

StageFunction = Callable[[dict[str, Any], dict[str, str], dict[str, str]], Mapping[str, float] | None]

#: Output files that are attached to the stage's MLflow run.
ARTIFACT_SUFFIXES = {".json", ".png", ".md", ".csv", ".graphml", ".html", ".yaml"}
MAX_ARTIFACT_BYTES = 50 * 2**20

log = logging.getLogger("topoloc")


def configure_logging(log_path: str | Path) -> None:
    """Log INFO and up to ``log_path``; warnings and errors also to stderr."""
    root = logging.getLogger()
    root.handlers.clear()
    root.setLevel(logging.INFO)
    file_handler = logging.FileHandler(log_path, mode="w")
    file_handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    console = logging.StreamHandler(sys.stderr)
    console.setLevel(logging.WARNING)
    console.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    root.addHandler(file_handler)
    root.addHandler(console)
    logging.captureWarnings(True)


def run_stage(smk: Any, stage: StageFunction) -> None:
    """Run ``stage`` for the Snakemake job ``smk`` inside its MLflow run.

    Params are ``smk.params.conf`` (the config slice, logged as MLflow params);
    tags name the rule, wildcards, code digest and sha256 of every input. Bad
    input ends the job with one line on stderr: ``topoloc: <file or key>: <what>``.
    """
    log_path = Path(smk.log[0])
    log_path.parent.mkdir(parents=True, exist_ok=True)
    configure_logging(log_path)
    inputs = {name: str(value) for name, value in smk.input.items()}
    outputs = {name: str(value) for name, value in smk.output.items()}
    conf = dict(smk.params.conf)
    wildcards = dict(smk.wildcards.items())
    tags = {
        "mlflow.runName": " ".join([smk.rule, *(f"{k}={v}" for k, v in wildcards.items())]),
        "topoloc.code_digest": str(getattr(smk.params, "code", "")),
        **{f"topoloc.wildcards.{k}": str(v) for k, v in wildcards.items()},
        **{f"topoloc.input_sha256.{k}": sha256_file(v) for k, v in inputs.items() if Path(v).exists()},
    }
    log.info("rule %s: inputs %s -> outputs %s", smk.rule, inputs, outputs)
    try:
        with StageRun(smk.config["tracking"]["experiment"], smk.rule, tags, conf) as run:
            metrics = stage(conf, inputs, outputs) or {}
            run.log_metrics(metrics)
            for path in map(Path, outputs.values()):
                if path.is_file() and "".join(path.suffixes[-1:]) in ARTIFACT_SUFFIXES and path.stat().st_size <= MAX_ARTIFACT_BYTES:
                    run.log_artifact(path)
            log.info("done; MLflow run %s", run.run_id)
            for handler in logging.getLogger().handlers:
                handler.flush()
            run.log_artifact(log_path, "logs")
    except InputError as err:
        log.error("%s", err)
        print(f"topoloc: {err}", file=sys.stderr)
        sys.exit(1)
