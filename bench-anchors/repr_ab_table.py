"""Medians, ranges and per-round ratios of bench-anchors/repr-ab.sh's JSON
lines (samples/s of one training step per side and round). A ratio is the
median of the rounds' ratios, each round's sides run within a minute of each
other; "above 1" counts the rounds where the first side was faster.

Usage: python3 bench-anchors/repr_ab_table.py OUT.jsonl [OUT2.jsonl ...]
"""
import collections, json, statistics, sys

rounds = collections.defaultdict(dict)
for i, path in enumerate(sys.argv[1:]):
    for line in open(path):
        if line.strip():
            r = json.loads(line)
            rounds[(i, r["round"])][r["bin"]] = r


def spread(v):
    return f"{statistics.median(v):.1f} ({min(v):.1f}–{max(v):.1f})"


sides = ["new", "old", "torch"]
full = [r for r in rounds.values() if all(s in r for s in sides)]
print(f"{len(full)} rounds")
for s in sides:
    v = [r[s]["samples_per_s"] for r in full]
    phases = [statistics.median(r[s][k] for r in full) for k in ("forward_ms", "backward_ms", "optimiser_ms")]
    print(f"{s}: {spread(v)} samples/s; forward, backward, optimiser ms {phases[0]:.0f}, {phases[1]:.0f}, {phases[2]:.1f}")
for a, b in [("new", "torch"), ("old", "torch"), ("new", "old")]:
    q = [r[a]["samples_per_s"] / r[b]["samples_per_s"] for r in full]
    print(f"{a} / {b}: {statistics.median(q):.2f} ({min(q):.2f}–{max(q):.2f}), above 1 in {sum(x > 1 for x in q)} of {len(q)}")
