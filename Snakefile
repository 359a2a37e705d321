# topoloc: map-based geolocalization from motion.
# The stages live in workflow/rules/*.smk; their logic in src/topoloc.
from snakemake.utils import min_version

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/download_osm.smk"
include: "workflow/rules/build_graph.smk"
include: "workflow/rules/render_drive.smk"
include: "workflow/rules/extract_odometry.smk"
include: "workflow/rules/segment_trajectory.smk"
include: "workflow/rules/trajectory.smk"
include: "workflow/rules/place.smk"
include: "workflow/rules/drive.smk"
include: "workflow/rules/localization.smk"
include: "workflow/rules/viewer.smk"
include: "workflow/rules/experiments.smk"
include: "workflow/rules/results_pages.smk"
include: "workflow/rules/common_regions.smk"
include: "workflow/rules/regions.smk"


rule all:
    default_target: True
    input:
        all_outputs(),
        expand(rules.report_html.output, region=REGION),
        expand(rules.write_results_pages.output, region=REGION),
        region_targets(),


onsuccess:
    finish_invocation(os.environ.get(INVOCATION_ENV), "FINISHED")


onerror:
    report_failures()
    finish_invocation(os.environ.get(INVOCATION_ENV), "FAILED")
    close_killed_runs()
