"""The reconstructor base (splitcam.recon.base): the fast-precision switch, and ``auto`` chosen by
measurement (splitcam.recon.precision)."""

from __future__ import annotations

import pytest


def test_precision_switch(monkeypatch: pytest.MonkeyPatch) -> None:
    from splitcam.recon import base, precision

    assert base.fast_precision("fp32", "cpu") is False
    assert base.fast_precision("bf16", "cpu") is True
    monkeypatch.setattr(precision, "_MEMO", {})
    monkeypatch.setattr(precision, "_cpu_flags", lambda: set())
    assert base.fast_precision("auto", "cpu") is False  # emulated bfloat16: not even measured
    with pytest.raises(ValueError, match="unknown precision"):
        base.fast_precision("fp16", "cpu")


@pytest.mark.parametrize("faster", [True, False])
def test_auto_follows_the_measurement_once_per_machine(monkeypatch, tmp_path, faster) -> None:
    """A CPU with native bfloat16 is measured, not trusted (an Intel Xeon with AVX512-BF16 runs
    float32 faster): auto takes the faster, remembers it in the cache file, and a new process
    (an empty memo) reads it back instead of measuring again."""
    from splitcam.recon import base, precision

    calls = []

    def fake_measure(device):
        calls.append(device)
        return precision.PrecisionChoice(faster, "measured", 1.0, 0.5 if faster else 2.0)

    monkeypatch.setenv(precision.CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(precision, "_MEMO", {})
    monkeypatch.setattr(precision, "_cpu_flags", lambda: {"avx512_bf16"})
    monkeypatch.setattr(precision, "measure", fake_measure)
    assert base.fast_precision("auto", "cpu") is faster
    assert base.fast_precision("auto", "cpu") is faster
    assert len(calls) == 1
    import json

    saved = json.loads(precision.cache_path().read_text())
    key = precision.device_key(__import__("torch").device("cpu"))
    assert saved[key]["fast"] is faster and "torch" in key
    monkeypatch.setattr(precision, "_MEMO", {})
    assert base.fast_precision("auto", "cpu") is faster and len(calls) == 1


def test_measure_times_both_and_takes_the_faster() -> None:
    """The real measurement on this CPU: both timings taken, the choice is the faster one and
    its reason gives the numbers."""
    from splitcam.recon.precision import measure

    choice = measure("cpu", steps=1, batch=2)
    assert choice.fp32_s > 0 and choice.bf16_s > 0
    assert choice.fast == (choice.bf16_s < choice.fp32_s)
    assert "ms in float32" in choice.reason


def test_float32_on_cuda_turns_tensorfloat32_off():
    """fp32 on a CUDA device must be float32: PyTorch's default lets cuDNN convolutions round
    to TensorFloat-32 (a 10-bit mantissa). On a CPU nothing changes."""
    import torch

    from splitcam.recon import base

    saved = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    try:
        torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = True
        base.strict_float32("cpu")
        assert torch.backends.cudnn.allow_tf32 and torch.backends.cuda.matmul.allow_tf32
        base.strict_float32(torch.device("cuda", 0))
        assert not torch.backends.cudnn.allow_tf32
        assert not torch.backends.cuda.matmul.allow_tf32
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = saved
