#!/usr/bin/env python3
"""Per-episode comparison of each ablations-near variant with the Full
variant: in how many of the shared evaluation episodes its normalised
reward is above, below or equal to Full's, with a two-sided sign test
(ties dropped). The episodes pair up because every variant is evaluated on
the same seeds (eval-PEG.json's `seed`); the script refuses files whose
seeds or episode counts differ.

Usage: versus_full.py [DIR]   (default: this script's directory;
       reads DIR/Full/eval-square.json and DIR/*/eval-square.json)
"""
import json
import math
import os
import sys


def load(path):
    d = json.load(open(path))
    r = d["report"]["normalised"]
    if not r:
        sys.exit(f"{path}: no episodes")
    return d["seed"], r


def sign_test(above, below):
    """Two-sided exact binomial p-value of `above` successes in above+below
    trials at p = 1/2."""
    n = above + below
    if n == 0:
        return 1.0
    k = min(above, below)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2**n
    return min(1.0, 2 * tail)


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    seed, full = load(os.path.join(root, "Full", "eval-square.json"))
    print("| variant | above Full | below | equal | sign test p | mean normalised (Full's) |")
    print("|---|---|---|---|---|---|")
    for name in sorted(os.listdir(root)):
        path = os.path.join(root, name, "eval-square.json")
        if name == "Full" or not os.path.isfile(path):
            continue
        s, r = load(path)
        if s != seed or len(r) != len(full):
            sys.exit(f"{path}: seed {s}, {len(r)} episodes; Full's: seed {seed}, {len(full)}")
        above = sum(a > b for a, b in zip(r, full))
        below = sum(a < b for a, b in zip(r, full))
        mean, fmean = sum(r) / len(r), sum(full) / len(full)
        print(
            f"| {name} | {above} | {below} | {len(r) - above - below} | "
            f"{sign_test(above, below):.2g} | {mean:.3f} ({fmean:.3f}) |"
        )


if __name__ == "__main__":
    main()
