"""Config validation (a bad key of any section stops `snakemake -n` with one line naming it, before any job runs) and
the shipped configs (each holds only what differs from what it stacks on, and config/README.md lists it)."""

from __future__ import annotations

import copy
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    ("yaml", "expected"),
    [
        ("encoding:\n  angle_bins: 3\n", "topoloc: config key 'encoding.angle_bins': 3 is less than the minimum of 4"),
        ("model:\n  cell: transformer\n", "topoloc: config key 'model.cell'"),
        ("train:\n  batch_size: 0\n", "topoloc: config key 'train.batch_size'"),
        ("dataset:\n  pathnodes: 4\n", "topoloc: config: unknown key under 'dataset'"),
        ("render:\n  conditions: [snow]\n", "topoloc: config key 'render.conditions.0': 'snow' is not one of"),
        ("render:\n  width: 10\n", "topoloc: config key 'render.width': 10 is less than the minimum of 64"),
        ("render:\n  buildings:\n    heights: 3\n", "topoloc: config: unknown key under 'render.buildings'"),
        ("place:\n  teach_condition: fog\n", "topoloc: place.repeat_conditions: must not contain the teach condition 'fog'"),
        ("place:\n  train:\n    conditions: [clear_noon, overcast, sunset, rain, fog, night]\n",
         "topoloc: place.train.conditions: keep at least one condition out of training"),
        ("place:\n  localize:\n    filter:\n      floor: 0\n", "topoloc: config key 'place.localize.filter.floor'"),
        ("place:\n  localize:\n    localizers: [place_loop, metric]\n",
         "topoloc: place.localize.localizers.1: unknown localizer 'metric'; choose from ['place_filter', "),
        ("localization:\n  localizers: [metric, place_filter]\n",
         "topoloc: localization.localizers.1: unknown localizer 'place_filter'; choose from ['hmm', "),
        ("odometry:\n  source: kitti_stereo\n  drives:\n    run1: {gps: g.csv}\n",
         "topoloc: config key 'odometry.drives.run1.sequence': drive run1 has no sequence, which odometry.source kitti_stereo needs"),
    ],
)
def test_bad_config_fails_with_one_line(tmp_path, yaml, expected):
    config = tmp_path / "bad.yaml"
    config.write_text(yaml)
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "--configfile", str(config)],
                            check=False, cwd=REPO, capture_output=True, text=True, env=env)
    assert result.returncode != 0
    lines = [line for line in result.stderr.splitlines() if line.startswith("topoloc:")]
    assert len(lines) == 1 and lines[0].startswith(expected), result.stderr[-2000:]


def test_load_fills_every_default_from_the_packaged_schema():
    from topoloc.config import SCHEMA_PATH, load

    assert SCHEMA_PATH.parent.name == "topoloc"  # shipped inside the package
    config = load(None, {"train": {"lr": 0.5}, "localization": {"hmm": {"cell_m": 4.0}}})
    assert config["train"]["lr"] == 0.5 and config["train"]["lr_schedule"] == "onecycle"
    assert config["localization"]["hmm"]["cell_m"] == 4.0 and config["localization"]["hmm"]["floor"] == 0.01
    assert config["odometry"]["stereo"]["max_features"] == 800 and config["region"] == {
        "name": "default", "osm_file": None, "place": None, "bbox": None}
    assert load(REPO / "config" / "config.yaml")["region"]["name"] == "helsinki"
    assert config["drive"]["demonstrations_from"] is None  # this region's own demonstrations
    assert load(None, {"drive": {"demonstrations_from": ["helsinki", "k00"]}})["drive"]["demonstrations_from"] == [
        "helsinki", "k00"]


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        ({"train": {"lr_shedule": "onecycle"}}, "config: unknown key under 'train': Additional properties are not allowed"),
        ({"train": {"batch_size": "64"}}, "config key 'train.batch_size': '64' is not of type 'integer'"),
        ({"localization": {"hmm": {"floor": 2}}}, "config key 'localization.hmm.floor': 2 is greater than the maximum of 1"),
        ({"drive": {"demonstrations_from": []}}, "config key 'drive.demonstrations_from': [] should be non-empty"),
        ({"drive": {"demonstrations_from": "k00"}},
         "config key 'drive.demonstrations_from': 'k00' is not of type 'array'"),
        ({"drive": {"demonstrations_from": ["k00", "k00"]}},
         "config key 'drive.demonstrations_from': ['k00', 'k00'] has non-unique"),
        ({"drive": {"demonstrations_from": [""]}}, "config key 'drive.demonstrations_from.0': '' should be non-empty"),
    ],
)
def test_load_rejects_a_bad_key_with_one_line_naming_it(overrides, expected):
    from topoloc.config import load
    from topoloc.errors import InputError

    with pytest.raises(InputError) as err:
        load(None, overrides)
    assert str(err.value).startswith(expected) and "\n" not in str(err.value)


def test_load_merges_several_files_in_order(tmp_path):
    from topoloc.config import load
    from topoloc.errors import InputError

    base, experiment = tmp_path / "base.yaml", tmp_path / "experiment.yaml"
    base.write_text("region: {name: x}\ndrive: {demonstrations: {routes: 20, val_routes: 2}}\n")
    experiment.write_text("drive: {demonstrations: {routes: 80}}\n")
    conf = load([base, experiment], {"drive": {"check": {"routes": 5}}})
    assert conf["region"]["name"] == "x"
    assert conf["drive"]["demonstrations"]["routes"] == 80  # the later file wins
    assert conf["drive"]["demonstrations"]["val_routes"] == 2  # and keeps what it does not set
    assert conf["drive"]["check"]["routes"] == 5
    experiment.write_text("- a list\n")
    with pytest.raises(InputError, match=rf"^{experiment}: a config file is a YAML mapping"):
        load([base, experiment])


def test_load_names_the_file(tmp_path):
    from topoloc.config import load
    from topoloc.errors import InputError

    bad = tmp_path / "bad.yaml"
    bad.write_text("region: {name: x, place: Somewhere}\nmodel:\n  cell: transformer\n")
    with pytest.raises(InputError, match=rf"^{bad}: config key 'model.cell': 'transformer' is not one of"):
        load(bad)
    bad.write_text("- a list\n")
    with pytest.raises(InputError, match=rf"^{bad}: a config file is a YAML mapping"):
        load(bad)


@pytest.mark.parametrize(
    ("odometry", "expected"),
    [
        ({"source": "kitti_poses", "drives": {"run1": {"gps": "g.csv", "ground_truth": "gt.txt"}}},
         "config key 'odometry.drives.run1.poses': drive run1 has no poses, which odometry.source kitti_poses needs"),
        ({"source": "kitti_poses", "drives": {"run1": {"poses": None, "gps": "g.csv"}}},
         "config key 'odometry.drives.run1.poses': drive run1 has no poses"),
        ({"source": "kitti_stereo", "drives": {"run1": {"poses": "p.txt", "gps": "g.csv"}}},
         "config key 'odometry.drives.run1.sequence': drive run1 has no sequence, which odometry.source kitti_stereo needs"),
        ({"source": "kitti_poses", "drives": {"run1": {"poses": "p.txt"}}},
         "config key 'odometry.drives.run1.gps': drive run1 has no gps file and odometry.origin is not set"),
        ({"source": "kitti_stereo", "drives": {}}, "config key 'odometry.drives': odometry.source kitti_stereo needs at least one drive"),
    ],
)
def test_each_kitti_source_needs_its_drive_keys(odometry, expected):
    from topoloc.config import load
    from topoloc.errors import InputError

    with pytest.raises(InputError) as err:
        load(None, {"odometry": odometry})
    assert str(err.value).startswith(expected) and "\n" not in str(err.value)


@pytest.mark.parametrize("source", ["kitti_poses", "kitti_stereo", "simulated", "rendered"])
def test_each_source_accepts_what_it_needs(source):
    from topoloc.config import load

    origin = {"lat": 48.98, "lon": 8.39, "heading_deg": 0.0}
    drives = {"kitti_poses": {"run1": {"poses": "p.txt", "gps": "g.csv"}, "run2": {"poses": "q.txt"}},
              "kitti_stereo": {"run1": {"sequence": "seq/00"}}}.get(source, {})  # simulated, rendered: no drives
    config = load(None, {"odometry": {"source": source, "drives": drives, "origin": origin}})
    assert config["odometry"]["source"] == source


@pytest.mark.parametrize("name", sorted(p.relative_to(REPO / "config").as_posix() for p in (REPO / "config").rglob("*.yaml")))
def test_every_shipped_config_is_valid_on_top_of_the_defaults(name):
    """What `snakemake --configfile config/<name>` parses: the file merged onto config/config.yaml, regions too."""
    import yaml

    from topoloc.config import load, region_configs

    conf = load(REPO / "config" / "config.yaml", yaml.safe_load((REPO / "config" / name).read_text()) or {})
    regions = region_configs(conf, REPO)
    assert conf["region"]["name"] not in regions
    assert all(r["region"]["name"] == n for n, r in regions.items())


CONFIG = REPO / "config" / "config.yaml"
_MISSING = object()


def stacking_problems(path: Path, stacks_on: Path | None, root: Path = REPO) -> list[str]:
    """What the config file ``path`` repeats of the config it stacks on, and the keys it names that the schema lacks.

    ``stacks_on``: the config file it is merged over (schema defaults filled); None: the schema's defaults alone.
    A mapping entry of ``regions`` stacks on its ``file`` (relative to ``root``) merged over the run's config.
    """
    import yaml

    from topoloc.config import load, region_configs, schema

    data = yaml.safe_load(path.read_text()) or {}
    problems = _problems(data, load(stacks_on), schema(), "")
    entries = [(index, entry) for index, entry in enumerate(data.get("regions") or []) if isinstance(entry, dict)]
    if entries:
        run = load(stacks_on, {k: v for k, v in data.items() if k != "regions"})
    for index, entry in entries:
        base = next(iter(region_configs({**run, "regions": [entry["file"]]}, root).values())) if "file" in entry else run
        problems += _problems({k: v for k, v in entry.items() if k != "file"}, base, schema(), f"regions.{index}.")
    return problems


def _problems(data: dict, reference: dict, node: dict, where: str) -> list[str]:
    """Keys of ``data`` equal to ``reference`` (a filled config, or the defaults a schema ``node`` fills in), or unknown."""
    problems = []
    properties, extra = node.get("properties", {}), node.get("additionalProperties")
    for key, value in data.items():
        sub = properties.get(key, extra if isinstance(extra, dict) else None)
        if sub is None:
            problems.append(f"{where}{key}: not a key of the schema")
            continue
        # A free-named entry (a drive of odometry.drives) that the reference lacks stacks on the schema's defaults.
        ref = reference.get(key, _MISSING if key in properties else _schema_defaults(sub))
        if ref is not _MISSING and _same(value, ref):
            problems.append(f"{where}{key}: repeats the value it stacks on ({value!r})")
        elif isinstance(value, dict) and ("properties" in sub or isinstance(sub.get("additionalProperties"), dict)):
            problems += _problems(value, ref if isinstance(ref, dict) else _schema_defaults(sub), sub, f"{where}{key}.")
    return problems


def _schema_defaults(node: dict) -> dict:
    """What the schema fills into an empty mapping of ``node``."""
    filled = {}
    for key, sub in node.get("properties", {}).items():
        if "default" in sub:
            value = copy.deepcopy(sub["default"])
            filled[key] = {**_schema_defaults(sub), **value} if isinstance(value, dict) else value
    return filled


def _same(a: object, b: object) -> bool:
    """Equal values of the same types all the way down (10 and 10.0, or 1 and true, differ)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


@pytest.mark.parametrize("name", sorted(p.relative_to(REPO / "config").as_posix() for p in (REPO / "config").rglob("*.yaml")))
def test_every_shipped_config_holds_only_what_differs_from_what_it_stacks_on(name):
    """config.yaml: from the schema's defaults; every other file: from config.yaml (schema defaults filled)."""
    path = REPO / "config" / name
    assert stacking_problems(path, None if path == CONFIG else CONFIG) == []
    assert f"| `{name}` |" in (REPO / "config" / "README.md").read_text(), "config/README.md's table lacks the file"


def test_the_default_config_differs_from_the_schema_only_in_its_region():
    """So the CLI without --config (the schema's defaults) and a region file read alone by `load` (the CLI, the
    benchmarks) give what the pipeline runs."""
    from topoloc.config import load

    default, schema_only = load(CONFIG), load(None)
    assert default["region"]["name"] != schema_only["region"]["name"]
    assert {k: v for k, v in default.items() if k != "region"} == {k: v for k, v in schema_only.items() if k != "region"}


def test_a_repeated_default_and_an_unknown_key_are_found(tmp_path):
    overlay = tmp_path / "overlay.yaml"
    overlay.write_text("train:\n  lr: 0.01\n  lr_shedule: constant\n  max_time_min: null\n"
                       "odometry:\n  drives:\n    run1: {poses: p.txt, gps: null}\n  simulated: {noise: {scale_error: 0.02}}\n"
                       "region: {name: helsinki, place: null, osm_file: town.osm}\n")
    assert stacking_problems(overlay, CONFIG, tmp_path) == [
        "train.lr: repeats the value it stacks on (0.01)",
        "train.lr_shedule: not a key of the schema",
        "odometry.drives.run1.gps: repeats the value it stacks on (None)",
        "odometry.simulated.noise.scale_error: repeats the value it stacks on (0.02)",
        "region.name: repeats the value it stacks on ('helsinki')",
        "region.place: repeats the value it stacks on (None)",
    ]
    config = tmp_path / "config.yaml"
    config.write_text("region: {name: town, osm_file: town.osm}\nencoding: {angle_bins: 20, heading_lookahead_m: 12}\n")
    assert stacking_problems(config, None, tmp_path) == ["encoding.angle_bins: repeats the value it stacks on (20)"]


def test_a_region_entry_that_repeats_its_file_is_found(tmp_path):
    (tmp_path / "town.yaml").write_text("region: {name: town, osm_file: town.osm}\nplace: {model_from: helsinki}\n")
    runs = tmp_path / "runs.yaml"
    runs.write_text("regions:\n  - file: town.yaml\n    place: {model_from: helsinki, seed: 3}\n"
                    "  - {region: {name: city, osm_file: city.osm}, graph: {crs: null}}\n")
    assert stacking_problems(runs, CONFIG, tmp_path) == [
        "regions.0.place.model_from: repeats the value it stacks on ('helsinki')",
        "regions.1.graph.crs: repeats the value it stacks on (None)",
    ]
