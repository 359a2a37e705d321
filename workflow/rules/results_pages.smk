# The docs site's results pages: one markdown page per task from this region's tables (docs/results/index.md).
from topoloc.report.write_results_pages import TASKS as RESULTS_TASKS


def results_pages_inputs(wildcards):
    """The region's tables the pages are made of; benchmark reports and experiment summaries are found at run time."""
    region = wildcards.region
    inputs = {
        "graph_stats": rules.build_graph.output.stats.format(region=region),
        "localization": rules.evaluate_localization.output.table.format(region=region),
        "evaluation": rules.evaluate_rnn.output.metrics.format(region=region),
        "accuracy": rules.evaluate_rnn.output.table.format(region=region),
        "dataset": rules.generate_dataset.output.table.format(region=region),
        "teach_repeat": rules.localize_repeat.output.table.format(region=region),
        "follow": rules.follow_route.output.table.format(region=region),
    }
    inputs |= {f"odometry_{drive}": rules.extract_odometry.output.stats.format(region=region, drive=drive) for drive in DRIVES}
    if config["drive"]["controllers_from"] is None:
        agents = [a for a in config["drive"]["follow"]["agents"] if a in ("dlm", "lp")]
        inputs |= {f"controller_{a}": f"results/{region}/drive/{a}/metrics.json" for a in agents}
    return inputs


rule write_results_pages:
    """One results page per task (headline table, the stages' tables, benchmarks and experiments found) and headline.md."""
    input:
        unpack(results_pages_inputs),
    output:
        **{task: f"results/{{region}}/pages/{task}.md" for task in RESULTS_TASKS},
        headline="results/{region}/pages/headline.md",
    params:
        conf={"region": REGION, "benchmarks_dir": "results/benchmarks",
              "experiments_dir": f"results/{REGION}/experiments", "stage_benchmarks_dir": f"results/{REGION}/benchmarks"},
        code=code("topoloc.report.write_results_pages"),
    log:
        "results/{region}/logs/write_results_pages.log",
    benchmark:
        "results/{region}/benchmarks/write_results_pages.tsv"
    script:
        "../scripts/write_results_pages.py"
