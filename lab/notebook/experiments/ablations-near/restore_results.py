#!/usr/bin/env python3
"""Writes runs/experiments/ablations_near/results.json from the variants
committed here, so that a partial run (`learner experiment --only NAME`) on a
fresh checkout merges their rows into its results table and chart instead of
writing its own row alone. An existing results.json is kept unless --force.

Usage (from the repository root):
    python3 lab/notebook/experiments/ablations-near/restore_results.py [--force]
"""
import json
import pathlib
import sys
import tomllib

HERE = pathlib.Path(__file__).resolve().parent
CONFIG = pathlib.Path("configs/experiments/ablations_near.toml")
OUT = pathlib.Path("runs/experiments/ablations_near/results.json")


def main() -> int:
    force = "--force" in sys.argv[1:]
    if OUT.exists() and not force:
        print(f"{OUT} exists; --force replaces it", file=sys.stderr)
        return 1
    cfg = tomllib.loads(CONFIG.read_text())
    rows = []
    for v in cfg["variant"]:
        # One evaluation per peg, named eval-PEG.json as the experiment names it.
        for path in sorted((HERE / v["name"]).glob("eval-*.json")):
            rows.append(
                {
                    "variant": v["name"],
                    "peg": path.stem.removeprefix("eval-"),
                    "report": json.loads(path.read_text())["report"],
                    "paper_completed": v.get("paper_completed"),
                }
            )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(rows, indent=1))
    print(f"{OUT}: {', '.join(r['variant'] for r in rows)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
