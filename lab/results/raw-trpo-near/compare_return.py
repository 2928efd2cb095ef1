"""TRPO from scratch on z against TRPO from scratch on raw inputs (issue 51 item 4): the
training return per 100k-step window, seeds pooled, and every validation's completions.

Reads lab/results/z-trpo-near/s*/ and lab/results/raw-trpo-near/s*/ (curve.csv: one row per
update of 2000 steps; validation.csv: 16 episodes every 80k steps).

    python3 lab/results/raw-trpo-near/compare_return.py
"""
import csv
import glob
import os

HERE = os.path.dirname(os.path.abspath(__file__))
GROUPS = {
    "z (full-near)": os.path.join(HERE, "../z-trpo-near"),
    "raw 16 px": HERE,
}
WINDOW = 100_000

for name, d in GROUPS.items():
    seeds = sorted(glob.glob(os.path.join(d, "s*/curve.csv")))
    curves = [list(csv.DictReader(open(p))) for p in seeds]
    last = max(int(c[-1]["env_steps"]) for c in curves)
    print(f"{name}: {len(curves)} seed(s), the longest to {last} steps")
    for lo in range(0, last, WINDOW):
        hi = min(lo + WINDOW, last)
        # A seed counts in a window only once it has run the whole window.
        full = [c for c in curves if int(c[-1]["env_steps"]) >= hi]
        vals = [float(r["mean_normalised"]) for c in full for r in c
                if lo < int(r["env_steps"]) <= hi]
        if vals:
            print(f"  {lo // 1000:4d}k-{hi // 1000:4d}k: normalised return "
                  f"{sum(vals) / len(vals):.3f} ({len(full)} seed(s), {len(vals)} updates)")
    done = total = 0
    for p in sorted(glob.glob(os.path.join(d, "s*/validation.csv"))):
        for r in csv.DictReader(open(p)):
            done += round(float(r["completed_insertion"]) * 16)
            total += 16
    print(f"  validations: {done} of {total} episodes completed")
