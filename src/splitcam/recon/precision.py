"""``--precision auto``: bfloat16 + channels-last or float32, chosen by a short measurement on the
machine at hand and remembered per device model and torch version.

Why measure rather than read CPU flags: native bfloat16 instructions do not make bfloat16 faster
everywhere. On an AMD EPYC with AVX512-BF16 a training step ran about 4x faster in bfloat16; on an
Intel Xeon with the same flag and no AMX it ran 1.4x *slower* (8 training steps of batch 80:
23.9 s against 17.0 s). So ``auto`` times the same few training steps of a physics network both
ways (:func:`measure`) and takes the faster, once per machine: the choice is kept in
``$SPLITCAM_CACHE/precision.json`` (default ``~/.cache/splitcam``) under the device's model and
torch's version, with the timings that made it. A CPU without native bfloat16 (AVX2 only:
emulated, several times slower) and Apple's MPS take float32 without measuring.

On a GPU the float32 arm is timed as a float32 run then trains: with TensorFloat-32 off
(:func:`~splitcam.recon.base.strict_float32`), at a batch of 128 (at batch 8 a GPU step is
bound by kernel launches, and both arms took 7 ms on an H200, while a run at batch 256 in full
float32 then took 56 ms a step). A choice made by an earlier method (``METHOD``) is measured again.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import platform
import statistics
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import torch

__all__ = [
    "CACHE_ENV",
    "PrecisionChoice",
    "cache_path",
    "choose_precision",
    "cpu_model",
    "device_key",
    "measure",
]

logger = logging.getLogger(__name__)

CACHE_ENV = "SPLITCAM_CACHE"
"""Environment variable naming splitcam's cache folder (default ``~/.cache/splitcam``)."""

_MEMO: dict[str, PrecisionChoice] = {}

METHOD = 2
"""The measurement's version, kept with each remembered choice: 2 times float32 with
TensorFloat-32 off and a GPU at batch 128."""
GPU_BATCH = 128


@dataclass(frozen=True)
class PrecisionChoice:
    """What ``auto`` runs in on one device, and why.

    Attributes:
        fast: bfloat16 + channels-last (else float32).
        reason: One line: what was measured, or why nothing was.
        fp32_s, bf16_s: Median seconds of the measured training step (None: not measured).
    """

    fast: bool
    reason: str
    fp32_s: float | None = None
    bf16_s: float | None = None


def cache_path() -> Path:
    """The file the choices are kept in."""
    root = os.environ.get(CACHE_ENV) or "~/.cache/splitcam"
    return Path(root).expanduser() / "precision.json"


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), or what :mod:`platform` knows of it."""
    with contextlib.suppress(OSError), open("/proc/cpuinfo", encoding="utf-8") as f:
        for line in f:
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def _cpu_flags() -> set[str]:
    with contextlib.suppress(OSError), open("/proc/cpuinfo", encoding="utf-8") as f:
        for line in f:
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    return set()


def device_key(device: torch.device) -> str:
    """The device's model and torch's version: what a choice is remembered under."""
    if device.type == "cuda":
        name = torch.cuda.get_device_name(device)
    else:
        name = f"{cpu_model()} ({torch.backends.cpu.get_cpu_capability()})"
    return f"{device.type}: {name}; torch {torch.__version__}"


def measure(
    device: torch.device | str, *, steps: int = 3, batch: int | None = None
) -> PrecisionChoice:
    """Time training steps (forward and backward) of a physics network of 4 blocks on ``batch``
    64x64 raw images (default 8 on a CPU, ``GPU_BATCH`` on a GPU), float32 (as training runs
    it: TensorFloat-32 off on CUDA) against bfloat16 autocast + channels-last, and choose the
    faster.

    bfloat16 counts only if it really runs: a convolution under the autocast must give bfloat16.
    """
    from ..patterns import builtin
    from ..physics.sensor import pattern_pixel_kernels
    from .networks import build_network

    device = torch.device(device)
    if batch is None:
        batch = GPU_BATCH if device.type == "cuda" else 8
    gen = torch.Generator().manual_seed(0)
    raw = torch.rand(batch, 1, 64, 64, generator=gen).to(device)
    kernels = pattern_pixel_kernels(builtin("D")).to(device)
    sigma = torch.full((batch,), 10.0, device=device)
    with torch.autocast(device.type, dtype=torch.bfloat16):
        probe = torch.nn.functional.conv2d(raw[:1], torch.ones(1, 1, 3, 3, device=device))
    runs = probe.dtype == torch.bfloat16
    times = {}
    for fast in (False, True) if runs else (False,):
        torch.manual_seed(0)
        net = build_network({"arch": "physics", "period": [2, 2], "blocks": 4}).to(device)
        x = raw
        if fast:
            net = net.to(memory_format=torch.channels_last)
            x = raw.contiguous(memory_format=torch.channels_last)

        def step(net=net, x=x, fast=fast) -> None:
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=fast):
                out = net(x, sigma, kernels)
            out.float().square().mean().backward()
            if device.type == "cuda":
                torch.cuda.synchronize(device)

        with _tensorfloat32(device, allowed=fast):
            step()  # warm-up: kernels chosen, memory allocated
            taken = []
            for _ in range(steps):
                t0 = time.perf_counter()
                step()
                taken.append(time.perf_counter() - t0)
        times[fast] = statistics.median(taken)
    if not runs:
        return PrecisionChoice(
            False, "bfloat16 autocast does not run convolutions here", times[False]
        )
    fp32_s, bf16_s = times[False], times[True]
    fast = bf16_s < fp32_s
    winner = "bfloat16 + channels-last" if fast else "float32"
    reason = (
        f"{winner}: a training step took {bf16_s * 1e3:.0f} ms in bfloat16 and "
        f"{fp32_s * 1e3:.0f} ms in float32 (ratio {fp32_s / bf16_s:.2f})"
    )
    return PrecisionChoice(fast, reason, fp32_s, bf16_s)


@contextlib.contextmanager
def _tensorfloat32(device: torch.device, *, allowed: bool):
    """Inside: TensorFloat-32 on CUDA as ``allowed`` says (float32 is timed without it, as
    ``strict_float32`` trains it); the backends' switches restored after."""
    if device.type != "cuda":
        yield
        return
    saved = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    if not allowed:
        torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    try:
        yield
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = saved


def _read_cache(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _remember(path: Path, key: str, choice: PrecisionChoice) -> None:
    """Keep the choice (best effort: a read-only home only means measuring again next time)."""
    with contextlib.suppress(OSError):
        from ..io import write_text

        path.parent.mkdir(parents=True, exist_ok=True)
        data = _read_cache(path)
        data[key] = {
            **asdict(choice),
            "method": METHOD,
            "measured": time.strftime("%Y-%m-%dT%H:%M:%S"),
        }
        write_text(path, json.dumps(data, indent=1) + "\n")


def choose_precision(device: torch.device | str) -> PrecisionChoice:
    """What ``auto`` runs a network in on ``device``: remembered, or measured now (a few
    seconds, said in the log) and remembered."""
    device = torch.device(device)
    if device.type == "mps":
        return PrecisionChoice(False, "float32: bfloat16 is not measured on MPS")
    if device.type == "cuda" and not torch.cuda.is_bf16_supported():
        return PrecisionChoice(False, "float32: this GPU has no bfloat16")
    if device.type == "cpu" and not {"avx512_bf16", "amx_bf16"} & _cpu_flags():
        return PrecisionChoice(False, "float32: this CPU has no native bfloat16 (emulated: slow)")
    key = device_key(device)
    if key in _MEMO:
        return _MEMO[key]
    path = cache_path()
    saved = _read_cache(path).get(key)
    if (
        isinstance(saved, dict)
        and isinstance(saved.get("fast"), bool)
        and saved.get("method") == METHOD
    ):
        fields = ("fast", "reason", "fp32_s", "bf16_s")
        choice = PrecisionChoice(**{k: saved.get(k) for k in fields})
    else:
        logger.info(f"precision auto: measuring float32 against bfloat16 on {key} (once)")
        choice = measure(device)
        _remember(path, key, choice)
    logger.info(f"precision auto on {key}: {choice.reason}")
    _MEMO[key] = choice
    return choice
