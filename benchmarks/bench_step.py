"""Training step time of the packed, physics and physics-with-learned-pattern networks, side by side
in one run (the issue-9 throughput target: physics within 10% of packed at the same precision).

    python benchmarks/bench_step.py    # 2 threads, bfloat16 autocast + channels-last, batch 16
"""

import time

import torch

from splitcam.physics.sensor import LearnableSplitterSensor, SplitterSensor
from splitcam.physics.system import ImagingSystem
from splitcam.recon.networks import build_network

torch.set_num_threads(2)
torch.manual_seed(0)


def bench(arch, learn, n=16, steps=8):
    sensor = LearnableSplitterSensor("D", init="support") if learn else SplitterSensor("D")
    net = build_network({"arch": arch, "period": [2, 2]})
    sys_ = ImagingSystem(sensor, net)
    sys_.channels_last = True
    net.to(memory_format=torch.channels_last)
    opt = torch.optim.Adam(sys_.parameters(), 1e-4)
    x = torch.rand(n, 3, 64, 64)

    def noise(raw):
        s = torch.rand(raw.shape[0]) * 30
        return raw + torch.randn_like(raw) * (s / 255).view(-1, 1, 1, 1), s

    ts = []
    for _ in range(steps):
        t = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out = sys_(x, noise)
        loss = ((out.float() - x) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        ts.append(time.perf_counter() - t)
    return sorted(ts[2:])[len(ts[2:]) // 2]


for arch, learn in [("packed", False), ("physics", False), ("physics", True)]:
    print(arch, learn, f"{bench(arch, learn) * 1e3:.0f} ms/step")
print("ratio physics / packed and joint / packed: see the lines above (same run)")
