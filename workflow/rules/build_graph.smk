rule build_graph:
    """Drivable road network as a topological graph with virtual nodes, tables, stats and map."""
    input:
        osm=rules.download_osm.output.osm,
    output:
        graph="results/{region}/graph/graph.graphml",
        edges="results/{region}/graph/edges.csv",
        nodes="results/{region}/graph/nodes.csv",
        virtual_segments="results/{region}/graph/virtual_segments.csv",
        stats="results/{region}/graph/stats.json",
        figure=report(
            "results/{region}/graph/map.png",
            caption="../report/map.rst",
            category="Road graph",
            labels={"region": "{region}", "figure": "map"},
        ),
    params:
        conf=config["graph"],
        code=code("topoloc.graph.build_graph"),
    log:
        "results/{region}/logs/build_graph.log",
    benchmark:
        "results/{region}/benchmarks/build_graph.tsv"
    script:
        "../scripts/build_graph.py"
