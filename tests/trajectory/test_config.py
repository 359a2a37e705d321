"""Config validation of the trajectory sections: one line naming the key, before any job runs."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ("yaml", "expected"),
    [
        ("encoding:\n  angle_bins: 3\n", "topoloc: config key 'encoding.angle_bins': 3 is less than the minimum of 4"),
        ("model:\n  cell: transformer\n", "topoloc: config key 'model.cell'"),
        ("train:\n  batch_size: 0\n", "topoloc: config key 'train.batch_size'"),
        ("dataset:\n  pathnodes: 4\n", "topoloc: config: unknown key under 'dataset'"),
    ],
)
def test_bad_trajectory_config_fails_with_one_line(tmp_path, yaml, expected):
    config = tmp_path / "bad.yaml"
    config.write_text(yaml)
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--configfile", str(config)],
                            cwd=REPO, capture_output=True, text=True, env=env)
    assert result.returncode != 0
    lines = [line for line in result.stderr.splitlines() if line.startswith("topoloc:")]
    assert len(lines) == 1 and lines[0].startswith(expected), result.stderr[-2000:]
