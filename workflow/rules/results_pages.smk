# The docs site's results pages: one markdown page per task from this region's tables (docs/results/index.md).
from topoloc.report.write_results_pages import TASKS as RESULTS_TASKS


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
