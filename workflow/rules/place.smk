# Place recognition under appearance change and topometric teach-and-repeat localization (Cai & Wan).


rule render_places:
    """Place images at the network's input size: training routes (every condition), the teach drive, the repeat drives."""
    input:
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        places="results/{region}/places/{split}/places.npz",
        stats="results/{region}/places/{split}/stats.json",
        sheet=report(
            "results/{region}/places/{split}/sheet.png",
            caption="../report/place_sheet.rst",
            category="Place recognition",
            labels={"region": "{region}", "split": "{split}", "figure": "sample places"},
        ),
    wildcard_constraints:
        split="train|teach|repeat",
    params:
        conf=lambda wildcards: place_conf(wildcards.split),
        code=code("topoloc.place.render_places"),
    log:
        "results/{region}/logs/render_places_{split}.log",
    benchmark:
        "results/{region}/benchmarks/render_places_{split}.tsv"
    script:
        "../scripts/render_places.py"


rule train_retrieval:
    """Train the siamese place-recognition network (Lightning); the model is logged to MLflow with its signature."""
    input:
        places="results/{region}/places/train/places.npz",
    output:
        model="results/{region}/retrieval/model.ckpt",
        history="results/{region}/retrieval/history.csv",
        metrics="results/{region}/retrieval/train_metrics.json",
        figure=report(
            "results/{region}/retrieval/training.png",
            caption="../report/retrieval_training.rst",
            category="Place recognition",
            labels={"region": "{region}", "figure": "training"},
        ),
    params:
        conf={k: config["place"][k] for k in ("teach_condition", "threads", "pairs", "network", "train")}
        | {"localize": {"window": config["place"]["localize"]["window"]}},
        code=code("topoloc.place.train_retrieval"),
    log:
        "results/{region}/logs/train_retrieval.log",
    benchmark:
        "results/{region}/benchmarks/train_retrieval.tsv"
    threads: config["place"]["threads"]
    script:
        "../scripts/train_retrieval.py"


rule build_topometric_map:
    """One vertex per teach frame: embedding, path-integrated position, navigation command."""
    input:
        model=trained_in(config["place"]["model_from"], rules.train_retrieval.output.model),
        teach="results/{region}/places/teach/places.npz",
        graph=rules.build_graph.output.graph,
    output:
        map="results/{region}/topometric_map/map.npz",
        vertices="results/{region}/topometric_map/vertices.csv",
        stats="results/{region}/topometric_map/stats.json",
        figure=report(
            "results/{region}/topometric_map/map.png",
            caption="../report/topometric_map.rst",
            category="Place recognition",
            labels={"region": "{region}", "figure": "topometric map"},
        ),
    params:
        conf={k: config["place"][k] for k in ("seed", "threads", "odometry_noise", "command")}
        | {"localize": {"correlation_size": config["place"]["localize"]["correlation_size"]}},
        code=code("topoloc.place.build_topometric_map"),
    log:
        "results/{region}/logs/build_topometric_map.log",
    benchmark:
        "results/{region}/benchmarks/build_topometric_map.tsv"
    threads: config["place"]["threads"]
    script:
        "../scripts/build_topometric_map.py"


rule localize_repeat:
    """Repeat drives under every other condition localized on the map: network vs raw correlation; Tables 1/2-style."""
    input:
        model=trained_in(config["place"]["model_from"], rules.train_retrieval.output.model),
        map=rules.build_topometric_map.output.map,
        repeat="results/{region}/places/repeat/places.npz",
    output:
        frames="results/{region}/teach_repeat/frames.csv",
        summary="results/{region}/teach_repeat/summary.csv",
        metrics="results/{region}/teach_repeat/metrics.json",
        table=report(
            "results/{region}/teach_repeat/tables.md",
            caption="../report/teach_repeat_table.rst",
            category="Place recognition",
            labels={"region": "{region}", "figure": "per-condition tables"},
        ),
        bars=report(
            "results/{region}/teach_repeat/conditions.png",
            caption="../report/teach_repeat_bars.rst",
            category="Place recognition",
            labels={"region": "{region}", "figure": "localized per condition"},
        ),
        errors=report(
            "results/{region}/teach_repeat/errors.png",
            caption="../report/teach_repeat_errors.rst",
            category="Place recognition",
            labels={"region": "{region}", "figure": "error along the route"},
        ),
    params:
        conf={k: config["place"][k] for k in ("seed", "threads", "teach_condition", "repeat_conditions",
                                               "odometry_noise", "localize")}
        | {"train": {"conditions": config["place"]["train"]["conditions"]}},
        code=code("topoloc.place.localize_repeat"),
    log:
        "results/{region}/logs/localize_repeat.log",
    benchmark:
        "results/{region}/benchmarks/localize_repeat.tsv"
    threads: config["place"]["threads"]
    script:
        "../scripts/localize_repeat.py"
