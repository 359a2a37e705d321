# The cross-region summary of a run naming several regions (config key regions; common_regions.smk).

if REGION_CONFIGS:

    rule summarize_regions:
        """Localization per region and drive, every region of the run side by side (table, figure, MLflow)."""
        input:
            **{f"csv_{r}": f"results/{r}/localization/localization.csv" for r in ALL_REGIONS},
        output:
            csv="results/regions/summary.csv",
            table=report(
                "results/regions/summary.md",
                caption="../report/regions_table.rst",
                category="Regions",
                labels={"figure": "localization per region"},
            ),
            figure=report(
                "results/regions/summary.png",
                caption="../report/regions_figure.rst",
                category="Regions",
                labels={"figure": "localized share per region"},
            ),
        params:
            conf={"regions": ALL_REGIONS},
            code=code("topoloc.localization.summarize_regions"),
        log:
            "results/regions/logs/summarize_regions.log",
        benchmark:
            "results/regions/benchmarks/summarize_regions.tsv"
        script:
            "../scripts/summarize_regions.py"
