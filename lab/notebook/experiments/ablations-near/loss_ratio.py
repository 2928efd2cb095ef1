#!/usr/bin/env python3
"""The paper's Table "Ratio of Representation Test over Training Loss" for
the ablations-near variants: each loss's test mean over its training mean
at the last epoch of each variant's metrics.csv.

Usage: loss_ratio.py NAME=metrics.csv [NAME=metrics.csv ...]
"""
import csv
import math
import os
import sys

TERMS = [
    ("Optical flow (EPE)", "flow_epe_px"),
    ("End-effector pose", "ee_mse"),
    ("Contact", "contact_bce"),
    ("Pairing", "pairing_bce"),
]


def last_epoch(path):
    rows = list(csv.DictReader(open(path)))
    if not rows:
        sys.exit(f"{path}: no rows")
    last = max(int(r["epoch"]) for r in rows)
    split = {r["split"]: r for r in rows if int(r["epoch"]) == last}
    if set(split) != {"train", "test"}:
        sys.exit(f"{path}: epoch {last} lacks a train or a test row")
    return last, split


def main():
    cols = []
    for arg in sys.argv[1:]:
        # Names and paths may hold "=" themselves (d=16, runs/.../d=16/...):
        # the split is at the first "=" whose right side is a file.
        cuts = [i for i, c in enumerate(arg) if c == "="]
        found = [(arg[:i], arg[i + 1 :]) for i in cuts if os.path.isfile(arg[i + 1 :])]
        if not found:
            sys.exit(f"{arg}: expected NAME=metrics.csv, an existing file")
        name, path = found[0]
        cols.append((name, *last_epoch(path)))
    if not cols:
        sys.exit(__doc__)
    print("| loss | " + " | ".join(f"{n} (epoch {e})" for n, e, _ in cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for label, key in TERMS:
        cells = []
        for _, _, s in cols:
            tr, te = float(s["train"][key]), float(s["test"][key])
            cells.append("N/A" if math.isnan(tr) or math.isnan(te) or tr == 0 else f"{te / tr:.2f}")
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
