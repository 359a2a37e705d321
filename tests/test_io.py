"""Atomic outputs: temporaries under one pattern, removed by a rerun; results readable as the umask says."""

from __future__ import annotations

import os
import stat

import pytest

from topoloc.io import (
    TMP_PREFIX,
    atomic_path,
    copy_file,
    publish_dir,
    remove_temporaries,
    temporaries_of,
    temporary_dir,
    write_json,
)


@pytest.fixture()
def umask():
    """Set the process umask for one test."""
    saved = os.umask(0o022)
    yield lambda mask: os.umask(mask)
    os.umask(saved)


def mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize(("mask", "file_mode", "dir_mode"), [(0o022, 0o644, 0o755), (0o027, 0o640, 0o750), (0o077, 0o600, 0o700)])
def test_outputs_get_the_mode_of_the_umask(tmp_path, umask, mask, file_mode, dir_mode):
    umask(mask)
    write_json(tmp_path / "a.json", {"x": 1})
    copy_file(tmp_path / "a.json", tmp_path / "b.json")
    with temporary_dir(tmp_path / "images") as tmp:
        (tmp / "images").mkdir()
        publish_dir(tmp / "images", tmp_path / "images")
    assert mode(tmp_path / "a.json") == mode(tmp_path / "b.json") == file_mode
    assert mode(tmp_path / "images") == dir_mode


def test_temporaries_follow_one_pattern_and_a_rerun_removes_them(tmp_path):
    out = tmp_path / "train.parquet"
    with atomic_path(out) as tmp:
        assert tmp.name.startswith(f"{TMP_PREFIX}train.parquet.") and tmp.name.endswith(".parquet")
        assert temporaries_of(out) == [tmp]
    with temporary_dir(tmp_path / "image_0") as folder:
        assert folder.name.startswith(f"{TMP_PREFIX}image_0.")
    # What a killed job leaves: a temporary file, a folder of images; another output's temporary stays.
    (tmp_path / f"{TMP_PREFIX}train.parquet.x1y2.parquet").write_bytes(b"half")
    (tmp_path / f"{TMP_PREFIX}image_0.abc" / "image_0").mkdir(parents=True)
    (tmp_path / f"{TMP_PREFIX}image_0.abc" / "image_0" / "000000.png").write_bytes(b"png")
    other = tmp_path / f"{TMP_PREFIX}val.parquet.zz.parquet"
    other.write_bytes(b"another job's")
    removed = remove_temporaries([out, tmp_path / "image_0"])
    assert {p.name for p in removed} == {f"{TMP_PREFIX}train.parquet.x1y2.parquet", f"{TMP_PREFIX}image_0.abc"}
    assert sorted(p.name for p in tmp_path.iterdir()) == [other.name, "train.parquet"]
