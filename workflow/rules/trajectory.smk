rule generate_dataset:
    """Training trajectories as angle tokens (+ continuous features) and edge labels: simulated drives encoded like
    test drives (dataset.source simulated_drives) or DFS map paths (dfs, the paper); Table I."""
    input:
        graph=rules.build_graph.output.graph,
    output:
        train="results/{region}/dataset/train.parquet",
        val="results/{region}/dataset/val.parquet",
        stats="results/{region}/dataset/stats.json",
        table=report(
            "results/{region}/dataset/table_i.md",
            caption="../report/table_i.rst",
            category="Trajectory learning",
            labels={"region": "{region}", "figure": "Table I"},
        ),
    params:
        conf=dataset_conf(),
        code=code("topoloc.trajectory.generate_dataset"),
    log:
        "results/{region}/logs/generate_dataset.log",
    benchmark:
        "results/{region}/benchmarks/generate_dataset.tsv"
    script:
        "../scripts/generate_dataset.py"


rule train_rnn:
    """Train the trajectory RNN (Lightning); the model is logged to MLflow with its signature."""
    input:
        train=rules.generate_dataset.output.train,
        val=rules.generate_dataset.output.val,
        stats=rules.generate_dataset.output.stats,
    output:
        model="results/{region}/model/model.ckpt",
        history="results/{region}/model/history.csv",
        metrics="results/{region}/model/train_metrics.json",
    params:
        conf={"encoding": config["encoding"], "model": config["model"], "train": config["train"]},
        code=code("topoloc.trajectory.train_rnn"),
    log:
        "results/{region}/logs/train_rnn.log",
    benchmark:
        "results/{region}/benchmarks/train_rnn.tsv"
    threads: lambda wildcards: workflow.cores  # evaluated per job: a cluster profile sets it (set-threads)
    script:
        "../scripts/train_rnn.py"


rule evaluate_rnn:
    """Accuracy at the i-th position (Eq. 6) on training and held-out trajectories; Fig. 8a and 8b."""
    input:
        model=rules.train_rnn.output.model,
        history=rules.train_rnn.output.history,
        train_metrics=rules.train_rnn.output.metrics,
        train=rules.generate_dataset.output.train,
        val=rules.generate_dataset.output.val,
        graph_stats=rules.build_graph.output.stats,
    output:
        csv="results/{region}/evaluation/accuracy.csv",
        metrics="results/{region}/evaluation/metrics.json",
        table=report(
            "results/{region}/evaluation/accuracy.md",
            caption="../report/accuracy_table.rst",
            category="Trajectory learning",
            labels={"region": "{region}", "figure": "accuracy table"},
        ),
        loss_figure=report(
            "results/{region}/evaluation/fig8a_loss.png",
            caption="../report/fig8a.rst",
            category="Trajectory learning",
            labels={"region": "{region}", "figure": "Fig. 8a"},
        ),
        accuracy_figure=report(
            "results/{region}/evaluation/fig8b_accuracy.png",
            caption="../report/fig8b.rst",
            category="Trajectory learning",
            labels={"region": "{region}", "figure": "Fig. 8b"},
        ),
    params:
        conf={"evaluate": config["evaluate"], "region": config["region"]["name"]},
        code=code("topoloc.trajectory.evaluate_rnn"),
    log:
        "results/{region}/logs/evaluate_rnn.log",
    benchmark:
        "results/{region}/benchmarks/evaluate_rnn.tsv"
    script:
        "../scripts/evaluate_rnn.py"
