"""PyTorch anchor for the representation benchmark (docs/performance.md).

The same architecture as learner::models (the Full Model: RGB, depth, wrench
and proprioception encoders, product of experts, action-conditional flow,
contact, end-effector and pairing heads) and the same losses, written in
PyTorch by us for this comparison only. It times what the Rust bench
example `repr_bench` times, on random inputs of the same shapes:

  train   one Adam step at batch B (forward, the six losses, backward,
          update), THREADS intra-op threads
  infer   the z means of a batch of 1 or of 64 observations, THREADS
          intra-op threads (repr.sh passes 1)

Usage: bench.py train|infer BATCH STEPS THREADS [cpu|cuda]. With cuda the
model and the batch live on GPU 0 and each timed step ends with
torch.cuda.synchronize(), so the time is the GPU's, not the launch's.

Output: one JSON object per line, like the Rust side's.
"""

import json
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

SLOPE = 0.1


def act(x):
    return F.leaky_relu(x, SLOPE)


class Mlp(nn.Module):
    def __init__(self, widths):
        super().__init__()
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(widths, widths[1:]))

    def forward(self, x):
        for i, l in enumerate(self.layers):
            x = l(x)
            if i + 1 < len(self.layers):
                x = act(x)
        return x


def conv(cin, cout, k, stride):
    return nn.Conv2d(cin, cout, k, stride=stride, padding=(k - 1) // 2)


class Rgb(nn.Module):
    def __init__(self, d, side):
        super().__init__()
        ks = [7, 5, 5, 3, 3, 3]
        ch = [3, 16, 32, 64, 64, 128, d]
        self.convs = nn.ModuleList(conv(ch[i], ch[i + 1], ks[i], 2) for i in range(6))
        self.fc = nn.Linear(d * (side // 64) ** 2, 2 * d)

    def forward(self, x):
        maps = []
        for c in self.convs:
            x = act(c(x))
            maps.append(x)
        return self.fc(x.flatten(1)), maps


class Depth(nn.Module):
    def __init__(self, d, side, per_stage):
        super().__init__()
        ch = [16, 32, 64, 64, 128, d]
        layers, cin = [], 1
        for stage in range(6):
            for j in range(per_stage):
                layers.append(conv(cin, ch[stage], 3, 2 if j == 0 else 1))
                cin = ch[stage]
        self.convs = nn.ModuleList(layers)
        self.fc = nn.Linear(d * (side // 64) ** 2, 2 * d)

    def forward(self, x):
        for c in self.convs:
            x = act(c(x))
        return self.fc(x.flatten(1))


class Wrench(nn.Module):
    def __init__(self, d):
        super().__init__()
        ch = [6, 16, 32, 64, 128, 2 * d]
        self.convs = nn.ModuleList(nn.Conv1d(ch[i], ch[i + 1], 2, stride=2) for i in range(5))

    def forward(self, x):
        for i, c in enumerate(self.convs):
            x = c(x)
            if i < 4:
                x = act(x)
        return x.flatten(1)


def gaussian(p):
    d = p.shape[1] // 2
    return p[:, :d], F.softplus(p[:, d:]) + 1e-4


def poe(experts):
    prec = 1.0 + sum(1.0 / v for _, v in experts)
    weighted = sum(m / v for m, v in experts)
    var = 1.0 / prec
    return weighted * var, var


class Flow(nn.Module):
    def __init__(self, d):
        super().__init__()
        self.entry = nn.Conv2d(2 * d, 64, 1)
        ups, cin = [], 64
        for cout, skip in zip([64, 32, 32, 32], [128, 64, 64, 32]):
            ups.append(nn.ConvTranspose2d(cin, cout, 4, stride=2, padding=1))
            cin = cout + skip
        self.ups = nn.ModuleList(ups)
        self.flow = nn.Conv2d(cin, 2, 3, padding=1)
        self.mask = nn.Conv2d(cin, 1, 3, padding=1)

    def forward(self, h, maps):
        c = maps[5]
        b, d, s, _ = c.shape
        x = act(self.entry(torch.cat([c, h.view(b, d, 1, 1).expand(b, d, s, s)], 1)))
        for i, u in enumerate(self.ups):
            x = torch.cat([act(u(x)), maps[4 - i]], 1)
        m = self.mask(x)
        f = self.flow(x) * torch.sigmoid(m)
        up = lambda t: F.interpolate(t, scale_factor=4, mode="bilinear", align_corners=True)
        return up(f), up(m)


class Full(nn.Module):
    def __init__(self, d=128, side=128, per_stage=3):
        super().__init__()
        self.rgb = Rgb(d, side)
        self.depth = Depth(d, side, per_stage)
        self.wrench = Wrench(d)
        self.proprio = Mlp([8, 32, 64, 128, 2 * d])
        self.act_mlp = nn.ModuleList([nn.Linear(4, 32), nn.Linear(32, 32)])
        self.fuse = nn.ModuleList([nn.Linear(d + 32, 128), nn.Linear(128, d)])
        self.flow = Flow(d)
        self.contact = nn.Linear(d, 1)
        self.pairing = nn.Linear(d, 1)
        self.ee = Mlp([d, 128, 64, 32, 3])

    def encode(self, rgb, depth, wrench, proprio):
        p, maps = self.rgb(rgb)
        experts = [gaussian(p), gaussian(self.depth(depth)), gaussian(self.wrench(wrench)),
                   gaussian(self.proprio(proprio))]
        mu, var = poe(experts)
        return mu, var, maps

    def forward(self, rgb, depth, wrench, proprio, action, eps):
        mu, var, maps = self.encode(rgb, depth, wrench, proprio)
        z = mu + var.sqrt() * eps
        a = action
        for l in self.act_mlp:
            a = act(l(a))
        h = torch.cat([z, a], 1)
        for l in self.fuse:
            h = act(l(h))
        flow, mask = self.flow(h, maps)
        return mu, var, z, self.contact(h)[:, 0], self.pairing(z)[:, 0], self.ee(h), flow, mask


def losses(out, y):
    mu, var, z, contact, pairing, ee, flow, mask = out
    paired = y["paired"]
    n = paired.sum().clamp(min=1.0)
    wmean = lambda per: (per * paired).sum() / n
    epe = ((flow - y["flow"]).pow(2).sum(1) + 1e-8).sqrt().flatten(1).mean(1)
    bce = F.binary_cross_entropy_with_logits
    m = bce(mask, y["mask"], reduction="none").flatten(1).mean(1)
    c = bce(contact, y["contact"], reduction="none")
    e = (ee - y["ee"]).pow(2).mean(1)
    p = bce(pairing, paired)
    kl = 0.5 * (var + mu.pow(2) - 1.0 - var.log()).sum(1).mean()
    return 10 * wmean(epe) + wmean(m) + wmean(c) + 0.5 * p + wmean(e) + 0.05 * kl


def batch(b, s, d):
    g = torch.Generator().manual_seed(1)
    r = lambda *shape: torch.randn(*shape, generator=g)
    x = (r(b, 3, s, s), r(b, 1, s, s), r(b, 6, 32), r(b, 8))
    y = {
        "flow": r(b, 2, s, s),
        "mask": (r(b, 1, s, s) > 0).float(),
        "contact": (r(b) > 0).float(),
        "paired": (r(b) > 0).float(),
        "ee": r(b, 3),
    }
    return x, r(b, 4), r(b, d), y


def median(xs):
    xs = sorted(xs)
    return xs[len(xs) // 2]


def main():
    what, b, steps, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    dev = torch.device(sys.argv[5] if len(sys.argv) > 5 else "cpu")
    sync = torch.cuda.synchronize if dev.type == "cuda" else (lambda: None)
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    d, s = 128, 128
    model = Full(d, s).to(dev)
    x, action, eps, y = batch(b, s, d)
    x = tuple(t.to(dev) for t in x)
    action, eps = action.to(dev), eps.to(dev)
    y = {k: v.to(dev) for k, v in y.items()}
    side = "pytorch" if dev.type == "cpu" else "pytorch-cuda"
    times = []
    if what == "train":
        opt = torch.optim.Adam(model.parameters(), lr=1e-4, betas=(0.5, 0.999))
        # Forward with losses, backward, optimiser: exact on the CPU (eager);
        # on a GPU only the total counts.
        phases = []
        for i in range(steps + 2):
            t = time.perf_counter()
            opt.zero_grad()
            loss = losses(model(*x, action, eps), y)
            t_fwd = time.perf_counter()
            loss.backward()
            t_bwd = time.perf_counter()
            opt.step()
            sync()
            if i >= 2:
                end = time.perf_counter()
                times.append(end - t)
                phases.append((t_fwd - t, t_bwd - t_fwd, end - t_bwd))
        step = median(times)
        phase = lambda k: round(1e3 * median([p[k] for p in phases]), 1)
        print(json.dumps({"side": side, "what": "train", "batch": b, "threads": threads,
                          "step_s": step, "samples_per_s": b / step, "steps": steps,
                          "torch": torch.__version__, "forward_ms": phase(0),
                          "backward_ms": phase(1), "optimiser_ms": phase(2)}))
    else:
        model.eval()
        with torch.no_grad():
            for i in range(steps + 3):
                t = time.perf_counter()
                mu, _, _ = model.encode(*x)
                _ = mu.reshape(-1).tolist()
                if i >= 3:
                    times.append(time.perf_counter() - t)
        per = median(times)
        print(json.dumps({"side": side, "what": "infer", "batch": b, "threads": threads,
                          "batch_s": per, "per_obs_ms": 1e3 * per / b, "steps": steps,
                          "torch": torch.__version__}))


if __name__ == "__main__":
    main()
