"""Table of medians and ranges per side of a representation benchmark's JSON
lines (bench-anchors/repr.sh, repr-gpu.sh): samples/s for training steps,
ms per observation for inference.

Usage: python3 bench-anchors/repr_table.py OUT.jsonl
"""
import json, sys, collections, statistics
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
by = collections.defaultdict(list)
for r in rows:
    key = (r["what"], r["batch"], r["threads"])
    v = r["samples_per_s"] if r["what"] == "train" else r["per_obs_ms"]
    by[key + (r["side"],)].append(v)
print("| what | batch | threads | side | median | range | rounds |")
print("|---|---|---|---|---|---|---|")
for k in sorted(by):
    v = sorted(by[k]); unit = "samples/s" if k[0] == "train" else "ms/observation"
    print(f"| {k[0]} | {k[1]} | {k[2]} | {k[3]} | {statistics.median(v):.3f} {unit} | {v[0]:.3f}–{v[-1]:.3f} | {len(v)} |")
