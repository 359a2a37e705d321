"""The stage glue: leftovers of a killed run removed first; bad input ends the job with one line, in its log."""

from __future__ import annotations

import logging
from pathlib import Path
from types import SimpleNamespace

import pytest

from topoloc.errors import InputError
from topoloc.io import TMP_PREFIX
from topoloc.stage import failure_line, run_stage


class Items(dict):
    """What Snakemake's named lists offer to the stage glue: ``items()`` and, for log, indexing."""


def job(tmp_path: Path) -> SimpleNamespace:
    return SimpleNamespace(rule="make_table", input=Items(), output=Items(table=str(tmp_path / "out" / "table.csv")),
                           params=SimpleNamespace(conf={"k": 1}, code="digest"), log=[str(tmp_path / "logs" / "t.log")],
                           wildcards=Items(region="r"), config={"tracking": {"experiment": "stage-test"}})


class NoRun:
    """Stands in for the MLflow run (tested in test_tracking): the glue around it is under test here."""

    run_id = "none"

    def __init__(self, *args):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def log_metrics(self, metrics):
        pass

    def log_artifact(self, *args):
        pass


@pytest.fixture()
def store(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("topoloc.stage.StageRun", NoRun)
    root = logging.getLogger()
    saved = root.handlers[:], root.level
    yield tmp_path
    for handler in root.handlers:
        handler.close()
    root.handlers[:], root.level = saved
    logging.captureWarnings(False)


def test_bad_input_ends_the_log_with_one_line_and_prints_nothing(store, capsys):
    smk = job(store)
    leftover = store / "out" / f"{TMP_PREFIX}table.csv.k1ll3d.csv"
    leftover.parent.mkdir()
    leftover.write_text("half a table")
    seen = []

    def stage(conf, inputs, outputs):
        seen.append(sorted(p.name for p in Path(outputs["table"]).parent.iterdir()))
        raise InputError("data/poses.txt:3", "a poses line needs finite numbers, got nan")

    with pytest.raises(SystemExit) as info:
        run_stage(smk, stage)
    assert info.value.code == 1
    assert seen == [[]]  # the killed run's temporary was gone before the stage started
    log = Path(smk.log[0]).read_text().splitlines()
    assert log[-1] == "topoloc: data/poses.txt:3: a poses line needs finite numbers, got nan"
    assert "topoloc:" not in capsys.readouterr().err  # printed once, by the workflow's onerror
    assert failure_line("make_table", {"region": "r"}, smk.log) == log[-1]


def test_a_crash_or_a_kill_gets_a_line_too(store):
    smk = job(store)

    def stage(conf, inputs, outputs):
        raise ZeroDivisionError("division by zero")

    with pytest.raises(SystemExit):
        run_stage(smk, stage)
    line = failure_line("make_table", {"region": "r"}, smk.log)
    assert line.startswith("topoloc: rule make_table (region=r) failed with ZeroDivisionError: division by zero")
    assert "Traceback" in Path(smk.log[0]).read_text()
    killed = failure_line("render_drive", {"drive": "d"}, [str(store / "no.log")])
    assert killed == f"topoloc: rule render_drive (drive=d) stopped without finishing (killed?); its log: {store / 'no.log'}"
