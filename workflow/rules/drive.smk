# Route following under appearance change (Cai & Wan): closed-loop simulator, expert demonstrations, Topo-DLM, Topo-LP,
# teach and repeat in closed loop.


rule simulate_demonstrations:
    """The expert's noisy drives on training routes away from the teach route, under the training conditions."""
    input:
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        demonstrations="results/{region}/drive/demonstrations.npz",
        stats="results/{region}/drive/demonstrations.json",
        sheet=report(
            "results/{region}/drive/demonstrations.png",
            caption="../report/drive_demonstrations.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "demonstrations"},
        ),
    params:
        conf=drive_conf(("seed", "camera", "vehicle", "episode", "lane", "expert", "noise", "demonstrations"),
                        ("route", "image", "command")),
        code=code("topoloc.drive.simulate_demonstrations"),
    log:
        "results/{region}/logs/simulate_demonstrations.log",
    benchmark:
        "results/{region}/benchmarks/simulate_demonstrations.tsv"
    script:
        "../scripts/simulate_demonstrations.py"


rule train_controller:
    """Train Topo-DLM or Topo-LP (Lightning; then DAgger rounds in the simulator and the closed-loop check on unseen
    routes) on this region's demonstrations, or on those of drive.demonstrations_from pooled; the model is logged to
    MLflow with its signature."""
    input:
        unpack(demonstration_inputs),
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        model="results/{region}/drive/{controller}/controller.ckpt",
        history="results/{region}/drive/{controller}/history.csv",
        metrics="results/{region}/drive/{controller}/metrics.json",
        figure=report(
            "results/{region}/drive/{controller}/training.png",
            caption="../report/drive_training.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "{controller} training"},
        ),
    wildcard_constraints:
        controller="dlm|lp",
    params:
        conf=lambda wildcards: controller_conf(wildcards.controller),
        code=code("topoloc.drive.train_controller"),
    log:
        "results/{region}/logs/train_controller_{controller}.log",
    benchmark:
        "results/{region}/benchmarks/train_controller_{controller}.tsv"
    threads: config["drive"]["threads"]
    script:
        "../scripts/train_controller.py"


rule follow_route:
    """Teach and repeat in closed loop: Topo-DLM, Topo-LP and replay, ground-truth and place localization, per condition."""
    input:
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
        **{f"controller_{a}": trained_in(config["drive"]["controllers_from"], f"results/{{region}}/drive/{a}/controller.ckpt")
           for a in config["drive"]["follow"]["agents"] if a in ("dlm", "lp")},
        model=trained_in(config["place"]["model_from"], rules.train_retrieval.output.model),
        map=rules.build_topometric_map.output.map,
    output:
        episodes="results/{region}/drive/follow/episodes.csv",
        summary="results/{region}/drive/follow/summary.csv",
        metrics="results/{region}/drive/follow/metrics.json",
        table=report(
            "results/{region}/drive/follow/tables.md",
            caption="../report/drive_table.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "success per condition"},
        ),
        paths=report(
            "results/{region}/drive/follow/paths.png",
            caption="../report/drive_paths.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "driven paths"},
        ),
        success=report(
            "results/{region}/drive/follow/success.png",
            caption="../report/drive_success.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "success bars"},
        ),
        strip=report(
            "results/{region}/drive/follow/strip.png",
            caption="../report/drive_strip.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "frame strip"},
        ),
        junctions="results/{region}/drive/follow/junctions.csv",
        traces="results/{region}/drive/follow/traces.csv.gz",
        junction_figure=report(
            "results/{region}/drive/follow/junctions.png",
            caption="../report/drive_junctions.rst",
            category="Route following",
            labels={"region": "{region}", "figure": "junctions taken"},
        ),
        **{f"movie_{a}": report(
            f"results/{{region}}/drive/follow/drive_{a}.gif",
            caption="../report/drive_movie.rst",
            category="Route following",
            labels={"region": "{region}", "figure": f"drive of {a}"},
        ) for a in config["drive"]["follow"]["agents"]},
    params:
        conf=drive_conf(("seed", "threads", "camera", "vehicle", "episode", "lane", "expert", "demonstrations", "follow"),
                        ("route", "image", "command", "teach_condition", "repeat_conditions", "odometry_noise", "localize")),
        code=code("topoloc.drive.follow_route"),
    log:
        "results/{region}/logs/follow_route.log",
    benchmark:
        "results/{region}/benchmarks/follow_route.tsv"
    threads: config["drive"]["threads"]
    script:
        "../scripts/follow_route.py"
