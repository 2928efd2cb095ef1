"""Loads `learner repr export`'s safetensors into the PyTorch twin of the
Full Model (bench-anchors/torch-repr/bench.py) and runs it on the inputs the
Rust test wrote; prints, as JSON, the largest absolute difference of each
output from the Rust side's and the largest magnitude of each.

Usage: torch_twin.py TWIN_DIR EXPORT_DIR CASE_FILE
"""

import json
import sys

import torch
from safetensors.torch import load_file

sys.path.insert(0, sys.argv[1])
import bench  # noqa: E402  (the twin)

spec = json.load(open(sys.argv[2] + "/representation-spec.json"))
m = spec["model"]
assert m["kind"] == "full", m
model = bench.Full(m["latent_dim"], m["image_size"], m["depth_convs_per_stage"])
# strict: every parameter of the twin is in the file and nothing else is.
model.load_state_dict(load_file(sys.argv[2] + "/representation.safetensors"), strict=True)
model.eval()
case = load_file(sys.argv[3])
torch.set_num_threads(1)
with torch.no_grad():
    x = (case["rgb"], case["depth"], case["wrench"], case["proprio"])
    mu, var, _ = model.encode(*x)
    eps = torch.zeros_like(mu)
    _, _, _, contact, pairing, ee, flow, mask = model(*x, case["action"], eps)
got = {"z_mean": mu, "z_var": var, "contact": contact, "pairing": pairing, "ee": ee,
       "flow": flow, "mask": mask}
out = {}
for k, v in got.items():
    want = case[k]
    assert v.shape == want.shape, (k, v.shape, want.shape)
    out[k] = {"max_abs_diff": (v - want).abs().max().item(), "max_abs": want.abs().max().item()}
print(json.dumps(out))
