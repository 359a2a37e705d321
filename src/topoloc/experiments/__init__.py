"""Experiments: long runs over noise levels, seeds or variants (workflow/rules/experiments.smk), off ``rule all``.

Each experiment has a stage module with ``run(conf, inputs, outputs)`` for one job (one level, seed or variant) and
``summarize(conf, inputs, outputs)`` for its aggregate (``summary.md`` and ``summary.json``).
"""
