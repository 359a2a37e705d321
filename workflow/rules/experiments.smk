# Experiments: long runs over noise levels, seeds or variants, not part of `rule all`. Run one with
# `snakemake experiment_<name> --cores N` (simulated, map_errors, city, rnn_ablation, drive_seeds); settings: experiments.* of
# the config. Each job is one MLflow run; each experiment ends in results/{region}/experiments/<name>/summary.md.
EXPERIMENT = "results/{region}/experiments"
LOCALIZATION_KEYS = ("localization", "segmentation", "encoding")


rule localize_simulated:
    """Localizers beside the oracle on simulated drives of several maps at one noise level."""
    input:
        unpack(simulated_inputs),
    output:
        starts=f"{EXPERIMENT}/simulated/{{level}}/starts.csv",
        figures=f"{EXPERIMENT}/simulated/{{level}}/figures.md",
        metrics=f"{EXPERIMENT}/simulated/{{level}}/metrics.json",
    wildcard_constraints:
        level="low|medium|high",
    params:
        conf=lambda wildcards: experiment_conf(*LOCALIZATION_KEYS, "graph", simulated=EXPERIMENTS["simulated"],
                                               level=wildcards.level),
        code=code("topoloc.experiments.simulated"),
    log:
        "results/{region}/logs/localize_simulated_{level}.log",
    benchmark:
        "results/{region}/benchmarks/localize_simulated_{level}.tsv"
    script:
        "../scripts/localize_simulated.py"


rule summarize_simulated:
    """The simulated-drives experiment over its noise levels: summary.md and summary.json."""
    input:
        **{f"starts_{level}": f"{EXPERIMENT}/simulated/{level}/starts.csv" for level in EXPERIMENTS["simulated"]["levels"]},
    output:
        summary=f"{EXPERIMENT}/simulated/summary.md",
        json=f"{EXPERIMENT}/simulated/summary.json",
        reliability=report(
            f"{EXPERIMENT}/simulated/reliability.png",
            caption="../report/experiment_reliability.rst",
            category="Localization",
            labels={"region": "{region}", "figure": "reliability, simulated drives"},
        ),
    params:
        conf={"simulated": EXPERIMENTS["simulated"]},
        code=code("topoloc.experiments.simulated"),
    log:
        "results/{region}/logs/summarize_simulated.log",
    benchmark:
        "results/{region}/benchmarks/summarize_simulated.tsv"
    script:
        "../scripts/summarize_simulated.py"


rule experiment_simulated:
    """Target: the simulated-drives experiment."""
    input:
        expand(rules.summarize_simulated.output, region=REGION),


rule localize_map_errors:
    """Localizers beside the oracle of the map they see, on drives simulated on a true network, one map-error type."""
    input:
        unpack(map_errors_inputs),
    output:
        starts=f"{EXPERIMENT}/map_errors/{{error}}/starts.csv",
        figures=f"{EXPERIMENT}/map_errors/{{error}}/figures.md",
        metrics=f"{EXPERIMENT}/map_errors/{{error}}/metrics.json",
    wildcard_constraints:
        error="|".join(["none", *MAP_ERROR_TYPES]),
    params:
        conf=lambda wildcards: experiment_conf(*LOCALIZATION_KEYS, "graph", map_errors=EXPERIMENTS["map_errors"],
                                               error=wildcards.error),
        code=code("topoloc.experiments.map_errors"),
    log:
        "results/{region}/logs/localize_map_errors_{error}.log",
    benchmark:
        "results/{region}/benchmarks/localize_map_errors_{error}.tsv"
    script:
        "../scripts/localize_map_errors.py"


rule summarize_map_errors:
    """The map-error experiment over its error types and levels: summary.md and summary.json."""
    input:
        **{f"starts_{error}": f"{EXPERIMENT}/map_errors/{error}/starts.csv"
           for error in ["none", *EXPERIMENTS["map_errors"]["errors"]]},
    output:
        summary=f"{EXPERIMENT}/map_errors/summary.md",
        json=f"{EXPERIMENT}/map_errors/summary.json",
        reliability=report(
            f"{EXPERIMENT}/map_errors/reliability.png",
            caption="../report/experiment_reliability.rst",
            category="Localization",
            labels={"region": "{region}", "figure": "reliability, map errors up to medium"},
        ),
    params:
        conf={"map_errors": EXPERIMENTS["map_errors"], "confirm_m": config["localization"]["evaluate"]["confirm_m"]},
        code=code("topoloc.experiments.map_errors"),
    log:
        "results/{region}/logs/summarize_map_errors.log",
    benchmark:
        "results/{region}/benchmarks/summarize_map_errors.tsv"
    script:
        "../scripts/summarize_map_errors.py"


rule experiment_map_errors:
    """Target: the map-error experiment."""
    input:
        expand(rules.summarize_map_errors.output, region=REGION),


rule localize_city:
    """The metric filter beside the oracle on simulated drives of city-scale maps at one noise level; its speed."""
    input:
        **{f"osm_{name}": EXPERIMENTS["city"]["osm"].get(name, f"experiments.city.osm has no file for {name}")
           for name in EXPERIMENTS["city"]["maps"]},
    output:
        starts=f"{EXPERIMENT}/city/{{level}}/starts.csv",
        speed=f"{EXPERIMENT}/city/{{level}}/speed.csv",
        figures=f"{EXPERIMENT}/city/{{level}}/figures.md",
        metrics=f"{EXPERIMENT}/city/{{level}}/metrics.json",
    wildcard_constraints:
        level="low|medium|high",
    params:
        conf=lambda wildcards: experiment_conf(*LOCALIZATION_KEYS, "graph", city=EXPERIMENTS["city"], level=wildcards.level),
        code=code("topoloc.experiments.city"),
    log:
        "results/{region}/logs/localize_city_{level}.log",
    benchmark:
        "results/{region}/benchmarks/localize_city_{level}.tsv"
    script:
        "../scripts/localize_city.py"


rule summarize_city:
    """The city-scale experiment over its noise levels: summary.md and summary.json."""
    input:
        **{f"metrics_{level}": f"{EXPERIMENT}/city/{level}/metrics.json" for level in EXPERIMENTS["city"]["levels"]},
    output:
        summary=f"{EXPERIMENT}/city/summary.md",
        json=f"{EXPERIMENT}/city/summary.json",
    params:
        conf={"city": EXPERIMENTS["city"]},
        code=code("topoloc.experiments.city"),
    log:
        "results/{region}/logs/summarize_city.log",
    benchmark:
        "results/{region}/benchmarks/summarize_city.tsv"
    script:
        "../scripts/summarize_city.py"


rule experiment_city:
    """Target: the city-scale experiment, and its viewers (viewer.smk)."""
    input:
        expand(rules.summarize_city.output, region=REGION),
        expand(rules.view_city.output, region=REGION),


rule ablate_rnn:
    """Train one variant of the trajectory RNN (cell, size, inputs) and localize with it from many starts."""
    input:
        unpack(ablation_inputs),
        train=rules.generate_dataset.output.train,
        val=rules.generate_dataset.output.val,
        stats=rules.generate_dataset.output.stats,
    output:
        model=f"{EXPERIMENT}/rnn_ablation/{{variant}}/model.ckpt",
        rows=f"{EXPERIMENT}/rnn_ablation/{{variant}}/rows.csv",
        metrics=f"{EXPERIMENT}/rnn_ablation/{{variant}}/metrics.json",
    wildcard_constraints:
        variant=r"(lstm|gru|rnn)-[0-9]+(-tokens)?",
    params:
        conf=lambda wildcards: experiment_conf(*LOCALIZATION_KEYS, "model", "train", rnn_ablation=ABLATION_RUN,
                                               variant=wildcards.variant),
        code=code("topoloc.experiments.rnn_ablation"),
    log:
        "results/{region}/logs/ablate_rnn_{variant}.log",
    benchmark:
        "results/{region}/benchmarks/ablate_rnn_{variant}.tsv"
    script:
        "../scripts/ablate_rnn.py"


rule ablate_rnn_baseline:
    """The token HMM and the oracle from many starts of the drives, beside the RNN variants."""
    input:
        unpack(ablation_inputs),
    output:
        rows=f"{EXPERIMENT}/rnn_ablation/hmm/rows.csv",
        metrics=f"{EXPERIMENT}/rnn_ablation/hmm/metrics.json",
    params:
        conf=experiment_conf(*LOCALIZATION_KEYS, rnn_ablation={"drives": ABLATION_RUN["drives"]}),
        code=code("topoloc.experiments.rnn_ablation"),
    log:
        "results/{region}/logs/ablate_rnn_baseline.log",
    benchmark:
        "results/{region}/benchmarks/ablate_rnn_baseline.tsv"
    script:
        "../scripts/ablate_rnn_baseline.py"


rule summarize_rnn_ablation:
    """The RNN ablation over its variants: summary.md and summary.json."""
    input:
        **{f"rows_{variant}": f"{EXPERIMENT}/rnn_ablation/{variant}/rows.csv"
           for variant in ["hmm", *EXPERIMENTS["rnn_ablation"]["variants"]]},
    output:
        summary=f"{EXPERIMENT}/rnn_ablation/summary.md",
        json=f"{EXPERIMENT}/rnn_ablation/summary.json",
    params:
        conf={"rnn_ablation": EXPERIMENTS["rnn_ablation"] | ABLATION_RUN},
        code=code("topoloc.experiments.rnn_ablation"),
    log:
        "results/{region}/logs/summarize_rnn_ablation.log",
    benchmark:
        "results/{region}/benchmarks/summarize_rnn_ablation.tsv"
    script:
        "../scripts/summarize_rnn_ablation.py"


rule experiment_rnn_ablation:
    """Target: the trajectory RNN ablation (the paper's setting: --configfile config/regions/kitti00.yaml)."""
    input:
        expand(rules.summarize_rnn_ablation.output, region=REGION),


SEEDS_AGENT = EXPERIMENTS["drive_seeds"]["agent"]
SEED_DIR = f"{EXPERIMENT}/drive_seeds/{{seed}}"


rule train_controller_seed:
    """train_controller with drive.train.seed set to {seed} (the closed-loop check included)."""
    input:
        unpack(demonstration_inputs),
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        model=f"{SEED_DIR}/train/controller.ckpt",
        history=f"{SEED_DIR}/train/history.csv",
        metrics=f"{SEED_DIR}/train/metrics.json",
        figure=f"{SEED_DIR}/train/training.png",
    wildcard_constraints:
        seed=r"[0-9]+",
    params:
        conf=lambda wildcards: deep_merge(controller_conf(SEEDS_AGENT),
                                          {"drive": {"train": {"seed": int(wildcards.seed), "log_model": False}}}),
        code=code("topoloc.drive.train_controller"),
    log:
        "results/{region}/logs/train_controller_seed_{seed}.log",
    benchmark:
        "results/{region}/benchmarks/train_controller_seed_{seed}.tsv"
    threads: config["drive"]["threads"]
    script:
        "../scripts/train_controller.py"


rule follow_route_seed:
    """follow_route with the controller of seed {seed} alone: teach and repeat of the region's teach route."""
    input:
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
        **{f"controller_{SEEDS_AGENT}": trained_in(config["drive"]["controllers_from"], f"{SEED_DIR}/train/controller.ckpt")},
        model=trained_in(config["place"]["model_from"], rules.train_retrieval.output.model),
        map=rules.build_topometric_map.output.map,
    output:
        episodes=f"{SEED_DIR}/follow/episodes.csv",
        summary=f"{SEED_DIR}/follow/summary.csv",
        metrics=f"{SEED_DIR}/follow/metrics.json",
        table=f"{SEED_DIR}/follow/tables.md",
        paths=f"{SEED_DIR}/follow/paths.png",
        success=f"{SEED_DIR}/follow/success.png",
        strip=f"{SEED_DIR}/follow/strip.png",
        junctions=f"{SEED_DIR}/follow/junctions.csv",
        junction_figure=f"{SEED_DIR}/follow/junctions.png",
    wildcard_constraints:
        seed=r"[0-9]+",
    params:
        conf=deep_merge(drive_conf(("seed", "threads", "camera", "vehicle", "episode", "lane", "expert", "demonstrations", "follow"),
                                   ("route", "image", "command", "teach_condition", "repeat_conditions", "odometry_noise", "localize")),
                        {"drive": {"follow": {"agents": [SEEDS_AGENT]}}}),
        code=code("topoloc.drive.follow_route"),
    log:
        "results/{region}/logs/follow_route_seed_{seed}.log",
    benchmark:
        "results/{region}/benchmarks/follow_route_seed_{seed}.tsv"
    threads: config["drive"]["threads"]
    script:
        "../scripts/follow_route.py"


rule check_controller_seed:
    """The closed-loop check of seed {seed}'s controller, trained in another region (drive.controllers_from), on unseen
    routes of this region."""
    input:
        controller=trained_in(config["drive"]["controllers_from"], f"{SEED_DIR}/train/controller.ckpt"),
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        metrics=f"{SEED_DIR}/check.json",
    wildcard_constraints:
        seed=r"[0-9]+",
    params:
        conf=controller_conf(SEEDS_AGENT),
        code=code("topoloc.experiments.drive_seeds"),
    log:
        "results/{region}/logs/check_controller_seed_{seed}.log",
    benchmark:
        "results/{region}/benchmarks/check_controller_seed_{seed}.tsv"
    threads: config["drive"]["threads"]
    script:
        "../scripts/check_controller_seed.py"


rule summarize_drive_seeds:
    """Route following over training seeds: per seed the check and teach and repeat, their mean and spread."""
    input:
        **{f"train_{seed}": trained_in(config["drive"]["controllers_from"], f"{EXPERIMENT}/drive_seeds/{seed}/train/metrics.json")
           for seed in EXPERIMENTS["drive_seeds"]["seeds"]},
        **{f"follow_{seed}": f"{EXPERIMENT}/drive_seeds/{seed}/follow/metrics.json" for seed in EXPERIMENTS["drive_seeds"]["seeds"]},
        **{f"check_{seed}": f"{EXPERIMENT}/drive_seeds/{seed}/check.json" for seed in EXPERIMENTS["drive_seeds"]["seeds"]
           if config["drive"]["controllers_from"]},
    output:
        summary=f"{EXPERIMENT}/drive_seeds/summary.md",
        routes=f"{EXPERIMENT}/drive_seeds/routes.md",
        json=f"{EXPERIMENT}/drive_seeds/summary.json",
    params:
        conf={"drive_seeds": EXPERIMENTS["drive_seeds"], "region": REGION,
              "train_region": config["drive"]["controllers_from"] or REGION,
              "localization": config["drive"]["follow"]["localization"],
              "conditions": config["place"]["repeat_conditions"]},
        code=code("topoloc.experiments.drive_seeds"),
    log:
        "results/{region}/logs/summarize_drive_seeds.log",
    benchmark:
        "results/{region}/benchmarks/summarize_drive_seeds.tsv"
    script:
        "../scripts/summarize_drive_seeds.py"


rule experiment_drive_seeds:
    """Target: route following over training seeds. With drive.controllers_from (another region's controllers, the
    paper's protocol: config/experiments/drive_transfer.yaml) run it in that region first: its seeds' controllers
    drive here."""
    input:
        expand(rules.summarize_drive_seeds.output, region=REGION),
