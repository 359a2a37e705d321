# Temporally consistent localization of the test drives, its evaluation, and the HTML report.


rule decode_trajectories:
    """Every configured localizer (raw, Strategy 1 and 2, HMM baseline, metric filter) on a drive, from a start every start_every_m."""
    input:
        unpack(decode_inputs),
    output:
        answers="results/{region}/localization/{drive}/answers.csv",
        stats="results/{region}/localization/{drive}/decoded.json",
        geojson="results/{region}/localization/{drive}/localization.geojson",
    params:
        conf=lambda wildcards: decode_conf(wildcards.drive),
        code=code("topoloc.localization.decode_trajectories"),
    log:
        "results/{region}/logs/decode_trajectories_{drive}.log",
    benchmark:
        "results/{region}/benchmarks/decode_trajectories_{drive}.tsv"
    script:
        "../scripts/decode_trajectories.py"


rule evaluate_localization:
    """Every localizer from many starts beside the oracle (the map's uniqueness limit); tables, CDF, Fig. 9 per drive."""
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
        starts="results/{region}/localization/starts.csv",
        metrics="results/{region}/localization/metrics.json",
        cdf=report(
            "results/{region}/localization/localized_cdf.png",
            caption="../report/localization_cdf.rst",
            category="Localization",
            labels={"region": "{region}", "figure": "distance to localized"},
        ),
        reliability=report(
            "results/{region}/localization/reliability.png",
            caption="../report/localization_reliability.rst",
            category="Localization",
            labels={"region": "{region}", "figure": "reliability of the confidence"},
        ),
        **fig9_outputs(),
    params:
        conf={"localization": config["localization"], "drives": DRIVES, "region": config["region"]["name"]},
        code=code("topoloc.localization.evaluate_localization"),
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
