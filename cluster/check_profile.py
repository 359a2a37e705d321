"""Check a Snakemake profile before submitting anything: every key must be a Snakemake option.

    python cluster/check_profile.py profiles/slurm [more profiles]

Prints nothing and exits 0 when every key of ``<profile>/config.yaml`` is an option of this Snakemake (with its
installed executor plugins, e.g. ``slurm-partition`` needs snakemake-executor-plugin-slurm); else one line per
profile naming the file and the first unknown key, exit 1. (Snakemake itself stops on such a key too, before
any job, but prints its whole usage first.)
"""

from __future__ import annotations

import sys
from pathlib import Path

import yaml


def unknown_keys(profile: str | Path) -> list[str]:
    """The keys of ``profile``'s config.yaml that name no option of Snakemake or of an installed plugin."""
    from snakemake.cli import get_argument_parser

    options = {s[2:] for action in get_argument_parser()._actions for s in action.option_strings if s.startswith("--")}
    data = yaml.safe_load((Path(profile) / "config.yaml").read_text()) or {}
    return [key for key in data if str(key) not in options]


def main(argv: list[str]) -> int:
    status = 0
    for profile in argv or ["profiles/slurm"]:
        path = Path(profile) / "config.yaml"
        if not path.is_file():
            print(f"topoloc: {path}: profile not found", file=sys.stderr)
            status = 1
            continue
        unknown = unknown_keys(profile)
        if unknown:
            print(f"topoloc: {path}: unknown profile key {unknown[0]!r} (not a snakemake option; a plugin missing?)",
                  file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
