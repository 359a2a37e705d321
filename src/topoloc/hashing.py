"""Content digests: input fingerprints for tracking, code digests for caching."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

_CHUNK = 1 << 20


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's bytes, or of a directory's files (names and bytes, sorted)."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_dir():
        for file in sorted(p for p in path.rglob("*") if p.is_file()):
            digest.update(str(file.relative_to(path)).encode())
            digest.update(bytes.fromhex(sha256_file(file)))
        return digest.hexdigest()
    with open(path, "rb") as handle:
        while chunk := handle.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def code_digest(paths: Iterable[str | Path]) -> str:
    """Short digest of the Python sources under ``paths`` (files or packages).

    Rules take it as a param, so editing a stage's library code reruns exactly
    the stages that import it. Only ``*.py`` files count; caches are ignored.
    """
    digest = hashlib.sha256()
    for root in sorted(Path(p) for p in paths):
        files = sorted(root.rglob("*.py")) if root.is_dir() else [root]
        for file in files:
            digest.update(str(file.name).encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()[:16]
