rule render_drive:
    """A stereo drive rendered from the map (route ren<RR> under one condition), in KITTI layout, with a contact sheet."""
    input:
        osm=rules.download_osm.output.osm,
        graph=rules.build_graph.output.graph,
    output:
        left=directory("results/{region}/render/{drive}/image_0"),
        right=directory("results/{region}/render/{drive}/image_1"),
        calib="results/{region}/render/{drive}/calib.txt",
        poses="results/{region}/render/{drive}/poses.txt",
        times="results/{region}/render/{drive}/times.txt",
        gps="results/{region}/render/{drive}/gps.csv",
        route="results/{region}/render/{drive}/route.csv",
        stats="results/{region}/render/{drive}/render.json",
        sheet=report(
            "results/{region}/render/{drive}/contact_sheet.png",
            caption="../report/contact_sheet.rst",
            category="Rendering",
            labels={"region": "{region}", "drive": "{drive}", "figure": "contact sheet"},
        ),
    wildcard_constraints:
        drive=r"ren\d+_[a-z][a-z0-9_]*",
    params:
        conf=lambda wildcards: {**config["render"], "drive": wildcards.drive},
        code=code("render", "motion", "graph/road_graph.py"),
    log:
        "results/{region}/logs/render_drive_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/render_drive_{drive}.tsv"
    script:
        "../scripts/render_drive.py"
