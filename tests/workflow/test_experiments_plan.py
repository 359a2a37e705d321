"""The experiments are rules off ``rule all``: a target per experiment plans one job per level, variant or seed."""

from __future__ import annotations

EXPERIMENT_RULES = {"localize_simulated", "summarize_simulated", "localize_map_errors", "summarize_map_errors",
                    "localize_city", "summarize_city", "view_city", "ablate_rnn",
                    "ablate_rnn_baseline", "summarize_rnn_ablation", "train_controller_seed", "follow_route_seed",
                    "check_controller_seed", "summarize_drive_seeds"}


def _local_maps(workflow) -> str:
    """A config that points the maps outside the checkout (../shared) at files in the scratch copy."""
    for name in ("kitti.osm", "a.osm.pbf", "b.osm.pbf"):
        (workflow.root / name).write_text("")
    return workflow.config("maps.yaml", "experiments:\n  simulated:\n    kitti00_osm: kitti.osm\n"
                                        "  city:\n    osm: {heidelberg: a.osm.pbf, malta: b.osm.pbf}\n"
                                        "  map_errors:\n    osm: {heidelberg: a.osm.pbf, malta: b.osm.pbf}\n")


def test_each_experiment_plans_one_job_per_level_variant_or_seed(workflow):
    maps = _local_maps(workflow)
    assert workflow.planned("experiment_simulated", "--configfile", maps) == {
        "localize_simulated": 3, "summarize_simulated": 1, "experiment_simulated": 1}
    assert workflow.planned("experiment_city", "--configfile", maps) == {
        "localize_city": 2, "summarize_city": 1, "view_city": 1, "experiment_city": 1}
    map_errors = workflow.planned("experiment_map_errors", "--configfile", maps)
    assert {k: map_errors[k] for k in ("localize_map_errors", "summarize_map_errors")} == {
        "localize_map_errors": 9, "summarize_map_errors": 1}  # `none` and the eight error types
    assert "train_rnn" in map_errors and "build_graph" in map_errors  # the region's map and its RNN
    missing = workflow.run("-n", "experiment_city", check=False)  # the maps beside the checkout are not here
    assert missing.returncode != 0 and "heidelberg.osm.pbf" in missing.stderr + missing.stdout
    ablation = workflow.planned("experiment_rnn_ablation")
    assert {k: ablation[k] for k in ("ablate_rnn", "ablate_rnn_baseline", "summarize_rnn_ablation")} == {
        "ablate_rnn": 6, "ablate_rnn_baseline": 1, "summarize_rnn_ablation": 1}
    seeds = workflow.planned("experiment_drive_seeds")
    assert {k: seeds[k] for k in ("train_controller_seed", "follow_route_seed", "summarize_drive_seeds")} == {
        "train_controller_seed": 3, "follow_route_seed": 3, "summarize_drive_seeds": 1}
    assert "train_controller" not in seeds  # the seeds' controllers, not the pipeline's


def test_the_levels_and_seeds_come_from_the_config(workflow):
    maps = _local_maps(workflow)
    override = workflow.config("few.yaml", "experiments:\n  simulated:\n    levels: [medium]\n"
                                           "  drive_seeds:\n    seeds: [4, 7]\n")
    assert workflow.planned("experiment_simulated", "--configfile", maps, override)["localize_simulated"] == 1
    assert workflow.planned("experiment_drive_seeds", "--configfile", override)["train_controller_seed"] == 2


def test_all_runs_no_experiment(workflow):
    assert not set(workflow.planned("all")) & EXPERIMENT_RULES
