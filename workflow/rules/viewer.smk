# The interactive viewers: one offline HTML file per drive, and one of teach and repeat (topoloc.viewer).
from topoloc.viewer.page import assets_digest

VIEWER_ASSETS = assets_digest()  # viewer.js & co. are not Python: their digest joins each rule's code digest


rule view_drive:
    """The interactive map of a drive: every localizer's answers over time, the truth, the metric filter's belief."""
    input:
        graph=rules.build_graph.output.graph,
        poses=rules.extract_odometry.output.poses,
        frames=rules.extract_odometry.output.frames,
        answers=rules.decode_trajectories.output.answers,
        stats=rules.decode_trajectories.output.stats,
        starts=rules.evaluate_localization.output.starts,
    output:
        html=report(
            "results/{region}/viewer/{drive}.html",
            caption="../report/viewer.rst",
            category="Viewer",
            labels={"region": "{region}", "drive": "{drive}", "figure": "interactive viewer"},
        ),
    wildcard_constraints:
        drive="|".join(re.escape(d) for d in DRIVES),  # the configured drives only (not teach_repeat.html)
    params:
        conf=lambda wildcards: {k: config[k] for k in ("localization", "segmentation", "encoding", "viewer")}
        | {"drive": wildcards.drive, "region": config["region"]["name"]},
        code=code("topoloc.viewer.view_drive") + VIEWER_ASSETS,
    log:
        "results/{region}/logs/view_drive_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/view_drive_{drive}.tsv"
    script:
        "../scripts/view_drive.py"


rule view_repeat:
    """The teach-and-repeat viewer: topometric map, repeat track, each method's localization and the camera frame;
    route following's routes, where its episodes failed, and each closed-loop drive replayed (vehicle, command)."""
    input:
        graph=rules.build_graph.output.graph,
        vertices=rules.build_topometric_map.output.vertices,
        frames=rules.localize_repeat.output.frames,
        repeat="results/{region}/places/repeat/places.npz",
        episodes=rules.follow_route.output.episodes,
        traces=rules.follow_route.output.traces,
    output:
        html=report(
            "results/{region}/viewer/teach_repeat.html",
            caption="../report/viewer_repeat.rst",
            category="Viewer",
            labels={"region": "{region}", "drive": "repeat drive", "figure": "teach and repeat viewer"},
        ),
    params:
        conf={"viewer": config["viewer"], "region": config["region"]["name"]},
        code=code("topoloc.viewer.view_repeat") + VIEWER_ASSETS,
    log:
        "results/{region}/logs/view_repeat.log",
    benchmark:
        "results/{region}/benchmarks/view_repeat.tsv"
    script:
        "../scripts/view_repeat.py"


rule view_city:
    """The city-scale viewer (experiment city): per map one drive, the metric filter's belief shrinking to one road."""
    input:
        **{f"osm_{name}": EXPERIMENTS["city"]["osm"].get(name, f"experiments.city.osm has no file for {name}")
           for name in EXPERIMENTS["city"]["maps"]},
    output:
        **{f"html_{name}": f"results/{{region}}/experiments/city/viewer/{name}.html" for name in EXPERIMENTS["city"]["maps"]},
    params:
        conf={k: config[k] for k in ("localization", "segmentation", "encoding", "graph", "viewer")}
        | {"city": EXPERIMENTS["city"]},
        code=code("topoloc.viewer.view_city") + VIEWER_ASSETS,
    log:
        "results/{region}/logs/view_city.log",
    benchmark:
        "results/{region}/benchmarks/view_city.tsv"
    script:
        "../scripts/view_city.py"
