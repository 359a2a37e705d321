rule extract_odometry:
    """A drive's odometry (simulated, KITTI poses or stereo VO), georeferenced, evaluated, frames labelled with edges."""
    input:
        unpack(odometry_inputs),
    output:
        poses="results/{region}/odometry/{drive}/poses.txt",
        frames="results/{region}/odometry/{drive}/frames.csv",
        stats="results/{region}/odometry/{drive}/odometry.json",
        figure=report(
            "results/{region}/odometry/{drive}/track.png",
            caption="../report/odometry_track.rst",
            category="Odometry",
            labels={"region": "{region}", "drive": "{drive}", "figure": "track"},
        ),
        evaluation=report(
            "results/{region}/odometry/{drive}/evaluation.png",
            caption="../report/odometry_evaluation.rst",
            category="Odometry",
            labels={"region": "{region}", "drive": "{drive}", "figure": "evaluation"},
        ),
    params:
        conf=lambda wildcards: {**config["odometry"], "drive": wildcards.drive},
        code=code("odometry", "motion"),
    log:
        "results/{region}/logs/extract_odometry_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/extract_odometry_{drive}.tsv"
    script:
        "../scripts/extract_odometry.py"
