"""The benchmarks: scripts that measure and print figures (speed, memory, accuracy against the issue's targets).

Run one from the repository root, without ``PYTHONPATH`` (``pip install -e .`` puts topoloc on the path)::

    python -m benchmarks.bench_odometry [--out results/benchmarks/bench_odometry.md]

Each prints its figures and writes the same markdown to ``--out`` (default ``results/benchmarks/<name>.md``), for
the docs' results pages. Experiments (many drives, seeds, noise levels or variants) are Snakemake rules:
``workflow/rules/experiments.smk``.
"""
