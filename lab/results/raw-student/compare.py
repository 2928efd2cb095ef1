"""Validation per DAgger round, students on z against students on raw inputs.

Reads each student's distill.csv (one row per round: env_steps, the share of
the round's 10 validation episodes that completed) and prints, per round,
the completed validation episodes pooled over the seeds present, and the
first round at which the pooled rate reached 50 %.

    python3 lab/results/raw-student/compare.py
"""
import csv
import glob
import os

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.abspath(os.path.join(HERE, "../../.."))
GROUPS = {
    "z (full-near)": sorted(glob.glob(os.path.join(ROOT, "lab/results/learned-student/s*-r12/distill.csv"))),
    "raw 16 px": sorted(glob.glob(os.path.join(HERE, "s*/distill.csv"))),
}
EPISODES = 10  # validation episodes per round (learned_student_*.toml)


def rounds(path):
    with open(path) as f:
        return [(int(r["round"]), int(r["env_steps"]), round(float(r["completed_insertion"]) * EPISODES))
                for r in csv.DictReader(f)]


for name, files in GROUPS.items():
    runs = [rounds(p) for p in files]
    n = min((len(r) for r in runs), default=0)
    print(f"{name}: {len(runs)} seed(s) ({', '.join(os.path.basename(os.path.dirname(p)) for p in files)})")
    first = None
    for k in range(n):
        done = sum(r[k][2] for r in runs)
        total = EPISODES * len(runs)
        if first is None and 2 * done >= total:
            first = runs[0][k][1]
        print(f"  round {k:2d} ({runs[0][k][1]:6d} steps): {done:2d} of {total} "
              f"[{' '.join(str(r[k][2]) for r in runs)}]")
    print(f"  first round at 50 % or more: {first if first is not None else 'not reached'} steps")
