"""Where PyTorch's training step of the Full Model goes, convolution by
convolution: torch.profiler over three steps of bench.py's model and losses
on the CPU, the self time per step of each convolution call by its input
shapes, then the step's total and its largest operations.

Usage: conv_profile.py BATCH THREADS   (with .venv-torch's python; a benchmark
aid, not a dependency). Ours, layer by layer: learner/examples/conv_bench.rs.
Not named profile.py, which would hide the standard library's module of
that name from torch.
"""
import collections
import sys

import torch
from torch.profiler import ProfilerActivity, profile

import bench

CONV_OPS = ("aten::convolution_backward", "aten::mkldnn_convolution", "aten::_convolution")
STEPS = 3


def main():
    b, threads = int(sys.argv[1]), int(sys.argv[2])
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    model = bench.Full(128, 128)
    x, action, eps, y = bench.batch(b, 128, 128)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4, betas=(0.5, 0.999))

    def step():
        opt.zero_grad()
        bench.losses(model(*x, action, eps), y).backward()
        opt.step()

    for _ in range(2):
        step()
    with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as p:
        for _ in range(STEPS):
            step()
    # The self time of an operation is its own, without what it calls: the
    # convolutions' rows add up to the time in their kernels.
    rows = []
    for e in p.key_averages(group_by_input_shape=True):
        if e.key in CONV_OPS:
            rows.append((e.self_cpu_time_total / STEPS / 1e3, e.key, str(e.input_shapes[:3])))
    print(f"convolutions, ms per step (batch {b}, {threads} threads), by input shapes:")
    for ms, key, shapes in sorted(rows, reverse=True):
        print(f"{ms:8.2f} {key:28s} {shapes}")
    by_op = collections.Counter()
    for e in p.key_averages():
        by_op[e.key] += e.self_cpu_time_total
    total = sum(by_op.values()) / STEPS / 1e3
    conv = sum(v for k, v in by_op.items() if k in CONV_OPS) / STEPS / 1e3
    print(f"step {total:.1f} ms, of which convolutions {conv:.1f} ms; the largest operations:")
    for key, v in by_op.most_common(15):
        print(f"{v / STEPS / 1e3:8.2f} ms {key}")


if __name__ == "__main__":
    main()
