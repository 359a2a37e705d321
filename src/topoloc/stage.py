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
from topoloc.io import remove_temporaries
from topoloc.tracking import StageRun

StageFunction = Callable[[dict[str, Any], dict[str, str], dict[str, str]], Mapping[str, float] | None]

#: Output files that are attached to the stage's MLflow run.
ARTIFACT_SUFFIXES = {".json", ".png", ".md", ".csv", ".graphml", ".html", ".yaml", ".gif"}
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
    console.addFilter(lambda record: getattr(record, "console", True))  # the failure line goes to the log only
    console.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    root.addHandler(file_handler)
    root.addHandler(console)
    logging.captureWarnings(True)


def run_stage(smk: Any, stage: StageFunction) -> None:
    """Run ``stage`` for the Snakemake job ``smk`` inside its MLflow run.

    Params are ``smk.params.conf`` (the config slice, logged as MLflow params);
    tags name the rule, wildcards, code digest and sha256 of every input.
    Temporaries of the job's outputs left by a killed run are removed first. Bad input ends the job
    with exit status 1 and, as the last line of its log, ``topoloc: <file or key>: <what>``; the
    workflow's ``onerror`` prints that line once, last (:func:`failure_line`).
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
    for tmp in remove_temporaries(outputs.values()):
        log.info("removed %s, left by a killed run", tmp)
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
        _end_with_line(log_path, f"{FAILURE_PREFIX}{err}")
    except Exception as err:
        log.exception("rule %s failed", smk.rule)
        _end_with_line(log_path, f"{FAILURE_PREFIX}rule {_job_name(smk.rule, wildcards)} failed with "
                                 f"{type(err).__name__}: {' '.join(str(err).split())[:300]} (the traceback is in {log_path})")


#: The start of the one line that tells the user why a job failed (the last line of its log).
FAILURE_PREFIX = "topoloc: "


def _job_name(rule: str, wildcards: Mapping[str, Any]) -> str:
    return f"{rule} ({', '.join(f'{k}={v}' for k, v in wildcards.items())})" if wildcards else rule


def _end_with_line(log_path: Path, line: str) -> None:
    """Log ``line`` (to the log file only), end the log with it bare, and exit with status 1."""
    log.error("%s", line.removeprefix(FAILURE_PREFIX), extra={"console": False})
    for handler in logging.getLogger().handlers:
        handler.flush()
    with log_path.open("a") as handle:
        handle.write(line + "\n")
    sys.exit(1)


def failure_line(rule: str, wildcards: Mapping[str, Any], log_paths: list[str]) -> str:
    """The line that says why a failed job failed: the ``topoloc: ...`` line its log ends with.

    A job whose log has no such line was stopped from outside (killed) or failed before the stage ran.
    """
    for log_path in log_paths:
        try:
            lines = Path(log_path).read_text(errors="replace").splitlines()
        except OSError:
            continue
        found = [line for line in lines if line.startswith(FAILURE_PREFIX)]
        if found:
            return found[-1]
    where = f"; its log: {', '.join(log_paths)}" if log_paths else ""
    return f"{FAILURE_PREFIX}rule {_job_name(rule, wildcards)} stopped without finishing (killed?){where}"
