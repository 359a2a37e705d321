# Several regions in one run (config key regions): each further region is this workflow again, loaded as a
# Snakemake module with its own config (the region's file or mapping merged onto this config), its rules
# named <region>_<rule>. Its rule, summarize_regions, is in regions.smk.
import re

from topoloc.config import region_configs

try:
    REGION_CONFIGS = region_configs(config, workflow.basedir)
except InputError as err:
    _fail(str(err))
if REGION in REGION_CONFIGS:
    _fail(f"regions: region {REGION!r} is named twice (it is this config's region.name)")
if "regions" in [REGION, *REGION_CONFIGS]:
    _fail("region.name: 'regions' is taken by the cross-region summary (results/regions/)")
for _index, (_region, _region_config) in enumerate(REGION_CONFIGS.items()):
    _osm_file = str(_region_config["region"]["osm_file"] or "")
    if _osm_file and not _osm_file.startswith(PYROSM_PREFIX) and not Path(_osm_file).is_file():
        _fail(f"regions ({_region}): {_osm_file}: OSM file not found (region.osm_file)")
ALL_REGIONS = [REGION, *REGION_CONFIGS]


def _rule_prefix(region):
    """Rule names of a further region: <region>_<rule>, the region's name made an identifier."""
    return re.sub(r"\W", "_", region)


def _scale_to_modules(prefixes):
    """--set-threads / --set-resources (the cluster profiles) name plain rules: give the same to every module's copy."""
    settings = workflow.resource_settings
    for parsed in (settings._parsed_overwrite_threads, settings._parsed_overwrite_resources):
        for rule, value in list(parsed.items()):
            for prefix in prefixes:
                parsed.setdefault(f"{prefix}_{rule}", value)


def region_targets():
    """What `snakemake all` builds beyond this config's region: every further region's `all`, and the summary."""
    if not REGION_CONFIGS:
        return []
    targets = [getattr(rules, f"{_rule_prefix(r)}_all").input for r in REGION_CONFIGS]
    return [*(path for paths in targets for path in paths), *rules.summarize_regions.output]


if REGION_CONFIGS:
    _scale_to_modules([_rule_prefix(r) for r in REGION_CONFIGS])
    for _region, _region_config in REGION_CONFIGS.items():
        workflow.module(name=f"region_{_rule_prefix(_region)}", snakefile=workflow.main_snakefile, config=_region_config)
        workflow.userule(rules=["*"], from_module=f"region_{_rule_prefix(_region)}", exclude_rules=[],
                         name_modifier=f"{_rule_prefix(_region)}_*")(lambda: None)
