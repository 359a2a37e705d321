"""Several regions in one run: region configs from files or mappings, bad input in one line; the summary stage."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from topoloc.config import load, region_configs
from topoloc.errors import InputError
from topoloc.localization.summarize_regions import run as summarize

KITTI = "region: {name: k00, osm_file: map.osm}\nodometry:\n  source: kitti_poses\n  drives: {gt: {poses: p.txt, gps: g.csv}}\n"


def test_each_region_is_its_file_or_mapping_merged_onto_the_config(tmp_path):
    (tmp_path / "k00.yaml").write_text(KITTI)
    config = load(overrides={"graph": {"virtual_node_spacing_m": 30}, "regions": [
        "k00.yaml", {"region": {"name": "bb", "osm_file": None, "bbox": [1, 2, 3, 4]}}]})
    regions = region_configs(config, tmp_path)
    assert list(regions) == ["k00", "bb"]
    assert regions["k00"]["odometry"]["source"] == "kitti_poses" and regions["bb"]["odometry"]["source"] == "rendered"
    assert all(r["graph"]["virtual_node_spacing_m"] == 30 for r in regions.values())  # the shared keys
    assert all(r["regions"] == [] for r in regions.values())
    assert region_configs(load()) == {}
    on_file = region_configs(load(overrides={"regions": [{"file": "k00.yaml", "region": {"name": "k01"}}]}), tmp_path)
    assert on_file["k01"]["odometry"]["source"] == "kitti_poses" and on_file["k01"]["region"]["osm_file"] == "map.osm"


@pytest.mark.parametrize(("entries", "message"), [
    (["k00.yaml", "k00.yaml"], "regions.1 (k00.yaml): region 'k00' is named twice in regions"),
    (["nope.yaml"], "regions.0: nope.yaml: cannot read the region's config file (No such file or directory)"),
    ([{"file": "nope.yaml"}], "regions.0.file: nope.yaml: cannot read the region's config file"),
    ([{"region": {"name": "x"}, "graph": {"no_such_key": 1}}], "regions.0: config: unknown key under 'graph'"),
    ([{"region": {"name": "x"}, "regions": ["k00.yaml"]}], "regions.0: a region's config cannot name regions itself"),
])
def test_bad_regions_fail_with_one_line(tmp_path, entries, message):
    (tmp_path / "k00.yaml").write_text(KITTI)
    with pytest.raises(InputError) as err:
        region_configs(load(overrides={"regions": entries}), tmp_path)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_the_summary_puts_regions_side_by_side(tmp_path):
    columns = {"starts": 10, "median_m": 250.0, "accuracy_after": 0.9, "oracle_resolved": 0.8}
    inputs = {}
    for region, shares in {"a": [1.0, 0.5], "b": [0.9, 0.25]}.items():
        frame = pd.DataFrame([{"drive": "d0", "localizer": name, "localized_share": share, **columns}
                              for name, share in zip(["oracle", "metric"], shares, strict=True)])
        inputs[f"csv_{region}"] = str(tmp_path / f"{region}.csv")
        frame.to_csv(inputs[f"csv_{region}"], index=False)
    outputs = {k: str(tmp_path / f"summary.{k}") for k in ("csv", "table", "figure")} | {"figure": str(tmp_path / "s.png")}
    metrics = summarize({"regions": ["a", "b"]}, inputs, outputs)
    assert metrics == {"a/d0/oracle/localized_share": 1.0, "a/d0/metric/localized_share": 0.5,
                       "b/d0/oracle/localized_share": 0.9, "b/d0/metric/localized_share": 0.25}
    table = pd.read_csv(outputs["csv"])
    assert table.region.tolist() == ["a", "a", "b", "b"] and table.columns[0] == "region"
    assert "| b | d0 | metric | 10 | 0.250 | 250 | 0.900 | 0.800 |" in Path(outputs["table"]).read_text()
    assert (tmp_path / "s.png").stat().st_size > 1000
    (tmp_path / "b.csv").write_text("drive,localizer\nd0,metric\n")
    with pytest.raises(InputError, match="no 'accuracy_after' column"):
        summarize({"regions": ["a", "b"]}, inputs, outputs)


def test_a_region_that_names_drives_has_those_only(tmp_path):
    """The run's drives (another region's data) are not merged into a region that names its own."""
    (tmp_path / "k00.yaml").write_text(KITTI)
    config = load(overrides={"region": {"name": "base", "osm_file": "map.osm"},
                             "odometry": {"source": "kitti_poses", "drives": {"orb": {"poses": "o.txt", "gps": "g.csv"}}},
                             "regions": [{"file": "k00.yaml", "odometry": {"drives": {"noisy": {
                                 "poses": "p.txt", "gps": "g.csv", "noise": {"scale_error": 0.01, "distance_noise": 0.0,
                                                                             "heading_drift_deg_per_100m": 0.5, "heading_noise_deg": 0.0}}}}},
                                 {"region": {"name": "bb", "osm_file": None, "bbox": [1, 2, 3, 4]}}]})
    regions = region_configs(config, tmp_path)
    assert sorted(regions["k00"]["odometry"]["drives"]) == ["gt", "noisy"]  # not the run's orb
    assert regions["k00"]["odometry"]["drives"]["noisy"]["noise_seed"] == 0  # filled and validated
    assert sorted(regions["bb"]["odometry"]["drives"]) == ["orb"]  # a region without drives of its own: the run's
