"""A config naming several regions: one DAG over all of them, bad input stopped before any job."""

from __future__ import annotations

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.kitti]


def test_two_regions_in_one_dag_and_bad_regions_in_one_line(workflow, kitti00):
    region = f"region: {{name: k00, osm_file: {kitti00 / 'map' / 'kitti_00.osm'}, place: null, bbox: null}}\n"
    workflow.config("k00.yaml", region + "odometry: {source: simulated}\n")
    jobs = workflow.planned("--configfile", workflow.config("two.yaml", "regions: [k00.yaml]\n"))
    assert jobs["build_graph"] == jobs["k00_build_graph"] == 1 and jobs["summarize_regions"] == 1
    assert jobs["k00_decode_trajectories"] == 1 and jobs["decode_trajectories"] == 1  # each region its own drives
    # the same stages in both regions, but rendered drives only where odometry.source is rendered
    main = {rule for rule in jobs if not rule.startswith("k00_")} - {"summarize_regions", "render_drive"}
    assert {rule.removeprefix("k00_") for rule in jobs if rule.startswith("k00_")} == main
    for name, text, expected in [
        ("twice.yaml", "regions: [k00.yaml, k00.yaml]\n", "topoloc: regions.1 (k00.yaml): region 'k00' is named twice"),
        ("missing.yaml", "regions: [{region: {name: m, osm_file: gone.osm}}]\n",
         "topoloc: regions (m): gone.osm: OSM file not found (region.osm_file)"),
    ]:
        proc = workflow.run("-n", "--configfile", workflow.config(name, text), check=False)
        lines = [line for line in proc.stderr.splitlines() if line.startswith("topoloc:")]
        assert proc.returncode == 1 and lines == [lines[0]] and lines[0].startswith(expected), proc.stderr


def test_networks_trained_in_one_region_drive_and_localize_in_another(workflow, kitti00):
    """The paper's protocol: the retrieval network and the controllers of the default map, teach and repeat on KITTI 00."""
    region = f"region: {{name: k00, osm_file: {kitti00 / 'map' / 'kitti_00.osm'}, place: null, bbox: null}}\n"
    workflow.config("k00.yaml", region + "odometry: {source: simulated}\n")
    text = ("regions:\n  - file: k00.yaml\n    place: {model_from: helsinki}\n"
            "    drive: {controllers_from: helsinki}\n")
    jobs = workflow.planned("--configfile", workflow.config("transfer.yaml", text))
    assert jobs["train_retrieval"] == 1 and jobs["train_controller"] == 2  # trained once, in the default region
    assert not {"k00_train_retrieval", "k00_train_controller", "k00_simulate_demonstrations"} & set(jobs)
    assert jobs["k00_follow_route"] == jobs["k00_build_topometric_map"] == jobs["k00_localize_repeat"] == 1
    assert jobs["k00_render_places"] == 2 and jobs["render_places"] == 3  # no training images where nothing trains
