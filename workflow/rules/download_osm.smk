rule download_osm:
    """Fetch (place, bbox) or copy (osm_file) the region's raw OSM data."""
    input:
        unpack(local_osm_file),
    output:
        osm=f"results/{{region}}/osm/region{RAW_OSM_SUFFIX}",
        source="results/{region}/osm/source.json",
    params:
        conf={**config["region"], "download": config["download"]},
        code=code("topoloc.osm.download_osm"),
    log:
        "results/{region}/logs/download_osm.log",
    benchmark:
        "results/{region}/benchmarks/download_osm.tsv"
    script:
        "../scripts/download_osm.py"
