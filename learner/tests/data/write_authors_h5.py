"""Writes one episode file in the layout of the authors' published data
(stanford-iprl-lab/multimodal_representation, README: triangle_real_data),
with values given by formulas that learner/tests/dataset_import.rs computes
again, so that every imported field can be checked.

Usage: write_authors_h5.py OUT.h5 EPISODE plain|gzip [FAULT]
FAULT (optional): missing-contact, proprio-7, image-float, forces-nan.
"""

import sys

import h5py
import numpy as np

T, H, W = 50, 128, 128


def fields(e):
    t = np.arange(T)[:, None, None]
    y = np.arange(H)[None, :, None]
    x = np.arange(W)[None, None, :]
    image = np.stack([(t * 7 + y * 3 + x * 5 + c + e) % 256 for c in range(3)], axis=-1)
    depth = (0.5 + 0.001 * (t + y + x + e))[..., None]
    fx = ((t + y + x) % 5 - 2) * 0.25
    fy = ((2 * t + x) % 3 - 1) * 0.5
    flow = np.stack([fx + 0 * y, fy + 0 * y], axis=-1)
    r = np.arange(50)[None, :, None]
    j = np.arange(6)[None, None, :]
    ts = np.arange(T)[:, None, None]
    forces = ts + 0.01 * r + 0.1 * j + e
    contact = np.zeros((T, 50), dtype=bool)
    contact[20 + e : 40, 49] = True
    steps = np.arange(T)[:, None]
    proprio = steps * 0.1 + np.arange(8)[None, :] + e
    action = steps * 0.01 + np.arange(4)[None, :] * 0.001 - e * 0.002
    ee_pos = np.stack([steps[:, 0] * 0.001 * (steps[:, 0] % 2), 0 * steps[:, 0], 0.2 + 0 * steps[:, 0]], axis=-1)
    return {
        "action": action,
        "contact": contact,
        "depth_data": depth.astype(np.float32),
        "ee_forces_continuous": forces,
        "ee_ori": np.tile([0.0, 0.0, 0.0, 1.0], (T, 1)),
        "ee_pos": ee_pos,
        "ee_vel": np.zeros((T, 3)),
        "ee_vel_ori": np.zeros((T, 3)),
        "ee_yaw": np.tile([1.0, 0.0, 0.0, 0.0], (T, 1)),
        "ee_yaw_delta": np.zeros((T, 4)),
        "image": image.astype(np.uint8),
        "joint_pos": np.zeros((T, 7)),
        "joint_vel": np.zeros((T, 7)),
        "optical_flow": flow.astype(np.float32),
        "proprio": proprio,
    }


def main():
    out, episode, storage = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    fault = sys.argv[4] if len(sys.argv) > 4 else None
    f = fields(episode)
    if fault == "missing-contact":
        del f["contact"]
    elif fault == "proprio-7":
        f["proprio"] = f["proprio"][:, :7]
    elif fault == "image-float":
        f["image"] = f["image"].astype(np.float32)
    elif fault == "forces-nan":
        f["ee_forces_continuous"][3, 10, 2] = np.nan
    kw = {"compression": "gzip", "chunks": True} if storage == "gzip" else {}
    with h5py.File(out, "w") as h:
        for k, v in f.items():
            h.create_dataset(k, data=v, **kw)


main()
