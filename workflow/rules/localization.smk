# Temporally consistent localization of the test drives, its evaluation, and the HTML report.
LOCALIZATION_CODE = ["localization/__init__.py", "localization/connectivity.py", "localization/decoders.py",
                     "localization/hmm.py", "localization/rnn.py", "localization/localize.py", "trajectory/model.py",
                     "graph/road_graph.py", "encoding.py"]


rule decode_trajectories:
    """RNN outputs on a test drive decoded raw, by Strategy 1 and 2 (hypotheses on the map), and by the HMM baseline."""
    input:
        model=rules.train_rnn.output.model,
        graph=rules.build_graph.output.graph,
        tokens=rules.segment_trajectory.output.tokens,
    output:
        table="results/{region}/localization/{drive}/decoded.csv",
        stats="results/{region}/localization/{drive}/decoded.json",
        geojson="results/{region}/localization/{drive}/strategy1.geojson",
    params:
        conf=lambda wildcards: {"localization": config["localization"], "drive": wildcards.drive},
        code=code(*LOCALIZATION_CODE, "localization/decode_trajectories.py"),
    log:
        "results/{region}/logs/decode_trajectories_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/decode_trajectories_{drive}.tsv"
    script:
        "../scripts/decode_trajectories.py"


rule evaluate_localization:
    """Step accuracy, consistency, distance until localized, accuracy after, per drive and aggregated; Fig. 9 per drive."""
    input:
        unpack(evaluation_inputs),
    output:
        table=report(
            "results/{region}/localization/localization.md",
            caption="../report/localization_table.rst",
            category="Localization",
            labels={"region": "{region}", "figure": "localization table"},
        ),
        csv="results/{region}/localization/localization.csv",
        metrics="results/{region}/localization/metrics.json",
        **fig9_outputs(),
    params:
        conf={"localization": config["localization"], "drives": DRIVES, "region": config["region"]["name"]},
        code=code(*LOCALIZATION_CODE, "localization/metrics.py", "localization/plot.py",
                  "localization/evaluate_localization.py"),
    log:
        "results/{region}/logs/evaluate_localization.log",
    benchmark:
        "results/{region}/benchmarks/evaluate_localization.tsv"
    script:
        "../scripts/evaluate_localization.py"


rule report_html:
    """The Snakemake HTML report of everything above (snakemake --report, run from this job)."""
    input:
        all_outputs(),
    output:
        html="results/{region}/report.html",
    params:
        conf={"region": config["region"]["name"]},
        snakefile=workflow.main_snakefile,
    log:
        "results/{region}/logs/report_html.log",
    benchmark:
        "results/{region}/benchmarks/report_html.tsv"
    script:
        "../scripts/report_html.py"
