"""Reference values from Pinocchio for robot-model's cross-check test.

Reads a JSON request on stdin: {"urdf": path, "frames": [names],
"samples": [{"q": [...], "v": [...], "a": [...]}]}; writes on stdout, per
sample, Pinocchio's frame poses, frame Jacobians and J̇v (LOCAL_WORLD_ALIGNED
and LOCAL), the mass matrix, gravity, nonlinear effects, RNEA, the Coriolis
matrix and ABA, with joint names so that the caller can match coordinates.
"""
import json
import sys

import numpy as np
import pinocchio as pin


def main():
    req = json.load(sys.stdin)
    model = pin.buildModelFromUrdf(req["urdf"])
    data = model.createData()
    names = list(model.names)[1:]
    idx_v = [model.joints[i].idx_v for i in range(1, model.njoints)]
    frame_ids = {name: model.getFrameId(name) for name in req["frames"]}
    for name, fid in frame_ids.items():
        if fid >= model.nframes:
            raise SystemExit(f"pinocchio has no frame {name}")
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    local = pin.ReferenceFrame.LOCAL
    out = {"pinocchio_version": pin.__version__, "joint_names": names, "idx_v": idx_v, "samples": []}
    for s in req["samples"]:
        # Requests are in Pinocchio's velocity order, one angle per joint;
        # a continuous joint's configuration is (cos, sin) in Pinocchio.
        angles, v, a = (np.array(s[k]) for k in ("q", "v", "a"))
        q = np.zeros(model.nq)
        for j in model.joints[1:]:
            if j.nq == 2:
                q[j.idx_q] = np.cos(angles[j.idx_v])
                q[j.idx_q + 1] = np.sin(angles[j.idx_v])
            else:
                q[j.idx_q] = angles[j.idx_v]
        res = {}
        pin.forwardKinematics(model, data, q, v, 0 * v)
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        frames = {}
        for name, fid in frame_ids.items():
            m = data.oMf[fid]
            frames[name] = {
                "translation": m.translation.tolist(),
                "rotation": m.rotation.tolist(),
                "jacobian_base": pin.getFrameJacobian(model, data, fid, lwa).tolist(),
                "jacobian_local": pin.getFrameJacobian(model, data, fid, local).tolist(),
                "jdot_v_base": pin.getFrameClassicalAcceleration(model, data, fid, lwa).vector.tolist(),
                "jdot_v_local": pin.getFrameAcceleration(model, data, fid, local).vector.tolist(),
            }
        res["frames"] = frames
        mass = pin.crba(model, data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T
        res["mass"] = mass.tolist()
        res["gravity"] = pin.computeGeneralizedGravity(model, data, q).tolist()
        res["nle"] = pin.nonLinearEffects(model, data, q, v).tolist()
        res["rnea"] = pin.rnea(model, data, q, v, a).tolist()
        res["coriolis"] = pin.computeCoriolisMatrix(model, data, q, v).tolist()
        res["aba"] = pin.aba(model, data, q, v, a).tolist()
        out["samples"].append(res)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
