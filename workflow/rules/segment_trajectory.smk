rule segment_trajectory:
    """Douglas-Peucker turns and distances of a drive's odometry, as tokens with ground-truth edge ids."""
    input:
        graph=rules.build_graph.output.graph,
        frames=rules.extract_odometry.output.frames,
    output:
        tokens="results/{region}/segments/{drive}/tokens.csv",
        segments="results/{region}/segments/{drive}/segments.csv",
        stats="results/{region}/segments/{drive}/segments.json",
        figure=report(
            "results/{region}/segments/{drive}/segments.png",
            caption="../report/segments.rst",
            category="Segmentation",
            labels={"region": "{region}", "drive": "{drive}", "figure": "segments"},
        ),
    params:
        conf=lambda wildcards: {
            "segmentation": config["segmentation"],
            "encoding": config["encoding"],
            "drive": wildcards.drive,
        },
        code=code("odometry", "encoding.py", "segmentation.py"),
    log:
        "results/{region}/logs/segment_trajectory_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/segment_trajectory_{drive}.tsv"
    script:
        "../scripts/segment_trajectory.py"
