"""Atomic file output: a failed stage never leaves a half-written result.

Every temporary file or folder of a stage is named ``.topoloc-tmp.<output name>.<random>`` and lives beside
the output it becomes (:data:`TMP_PREFIX`, :func:`temporaries_of`); a job killed with ``kill -9`` cannot
remove its own, so the next run of the stage removes them before it starts
(:func:`remove_temporaries`, called by :func:`topoloc.stage.run_stage`). Results get the permissions the
user's umask gives a new file (0644 with the usual umask 022), not the 0600 of :func:`tempfile.mkstemp`.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

#: The one pattern of every temporary file and folder a stage writes (``.topoloc-tmp.<output name>.*``).
TMP_PREFIX = ".topoloc-tmp."


def umask() -> int:
    """The process's umask (from ``/proc`` where it can be read without changing it)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _publish_mode(path: Path) -> None:
    """Give ``path`` the mode a new file (0666) or folder (0777) gets under the umask."""
    os.chmod(path, (0o777 if path.is_dir() else 0o666) & ~umask())


def temporary_name(path: str | Path) -> str:
    """The prefix of the temporaries of ``path`` (its name after :data:`TMP_PREFIX`)."""
    return f"{TMP_PREFIX}{Path(path).name}."


def temporaries_of(path: str | Path) -> list[Path]:
    """Temporary files and folders of the output ``path`` left beside it (by a killed job)."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    return sorted(path.parent.glob(f"{temporary_name(path)}*"))


def remove_temporaries(outputs: Iterable[str | Path]) -> list[Path]:
    """Remove the temporaries of ``outputs`` (safe while no other job writes these outputs); return them."""
    removed = []
    for output in outputs:
        for tmp in temporaries_of(output):
            if tmp.is_dir() and not tmp.is_symlink():
                shutil.rmtree(tmp, ignore_errors=True)
            else:
                tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file keeps the final suffix so that writers which infer the
    format from the extension (matplotlib, pandas) behave as for the real name.
    On any exception the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temporary_name(path), suffix="".join(path.suffixes))
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _publish_mode(tmp_path)
        os.replace(tmp_path, path)
    finally:
        tmp_path.unlink(missing_ok=True)


@contextmanager
def temporary_dir(path: str | Path) -> Iterator[Path]:
    """A fresh folder ``.topoloc-tmp.<name>.*`` beside the output ``path``, removed when the block ends.

    Move what it holds into place with :func:`publish_dir`.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=temporary_name(path), dir=path.parent))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def publish_dir(src: str | Path, dst: str | Path) -> None:
    """Replace the folder ``dst`` by ``src`` (a folder of a :func:`temporary_dir`), with the umask's mode."""
    src, dst = Path(src), Path(dst)
    _publish_mode(src)
    if dst.exists():
        shutil.rmtree(dst)
    os.replace(src, dst)


def write_json(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def copy_file(src: str | Path, dst: str | Path) -> None:
    """Copy ``src`` to ``dst`` atomically."""
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)
