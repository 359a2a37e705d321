"""drive.demonstrations_from: train_controller (and train_controller_seed) take the demonstrations of the regions it
names, each built by its own region's rule; DAgger without this region in the list is stopped before any job."""

from __future__ import annotations

import re

import pytest

pytestmark = pytest.mark.slow


def job_inputs(dry_run: str, rule: str) -> list[list[str]]:
    """The inputs of every job of ``rule`` that a dry run's output lists."""
    return [line.split(", ") for line in re.findall(rf"^rule {rule}:\n\s+input: (.*)$", dry_run, flags=re.M)]


def second_region(workflow) -> str:
    """A further region ``k1`` of the run (a map file that a dry run never reads) and the config that names it."""
    (workflow.root / "k1.osm").write_text("")
    workflow.config("k1.yaml", "region: {name: k1, osm_file: k1.osm, place: null, bbox: null}\n")
    return "regions: [k1.yaml]\n"


def test_controllers_train_on_the_demonstrations_of_the_regions_named(workflow):
    regions = second_region(workflow)
    pooled = workflow.config("pooled.yaml", regions + "drive: {demonstrations_from: [helsinki, k1]}\n")
    out = workflow.run("-n", "results/helsinki/drive/dlm/controller.ckpt", "--configfile", pooled).stdout
    demos = {"results/helsinki/drive/demonstrations.npz", "results/k1/drive/demonstrations.npz"}
    [inputs] = job_inputs(out, "train_controller")
    assert {path for path in inputs if path.endswith("demonstrations.npz")} == demos
    assert "results/helsinki/graph/graph.graphml" in inputs  # checked on this region's map
    assert len(job_inputs(out, "simulate_demonstrations")) == len(job_inputs(out, "k1_simulate_demonstrations")) == 1
    # Left out of the list, this region's demonstrations are neither read nor simulated; the seeds' controllers too.
    other = workflow.config("other.yaml", regions + "drive: {demonstrations_from: [k1]}\n")
    out = workflow.run("-n", "results/helsinki/drive/lp/controller.ckpt", "experiment_drive_seeds",
                       "--configfile", other).stdout
    trained = job_inputs(out, "train_controller") + job_inputs(out, "train_controller_seed")
    k1_only = ["results/k1/drive/demonstrations.npz"]
    assert len(trained) == 4 and all([p for p in inputs if p.endswith(".npz")] == k1_only for inputs in trained)
    assert not job_inputs(out, "simulate_demonstrations") and len(job_inputs(out, "k1_simulate_demonstrations")) == 1
    # DAgger drives this region's routes: refused in one line when the region is not in the list.
    dagger = workflow.config("dagger.yaml", regions + "drive: {demonstrations_from: [k1], dagger: {rounds: 1}}\n")
    proc = workflow.run("-n", "--configfile", dagger, check=False)
    lines = [line for line in proc.stderr.splitlines() if line.startswith("topoloc:")]
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("topoloc: drive.demonstrations_from: DAgger") and "helsinki" in lines[0]
    with_region = workflow.config("dagger_ok.yaml", regions + "drive: {demonstrations_from: [k1, helsinki], "
                                                              "dagger: {rounds: 1}}\n")
    jobs = workflow.planned("results/helsinki/drive/dlm/controller.ckpt", "--configfile", with_region)
    assert jobs["train_controller"] == 1
