"""The reconstructor base (splitcam.recon.base): the fast-precision switch."""

from __future__ import annotations

import pytest


def test_precision_switch(monkeypatch: pytest.MonkeyPatch) -> None:
    from splitcam.recon import base

    assert base.fast_precision("fp32", "cpu") is False
    assert base.fast_precision("bf16", "cpu") is True
    monkeypatch.setattr(base, "_cpu_has_native_bf16", lambda: True)
    assert base.fast_precision("auto", "cpu") is True
    monkeypatch.setattr(base, "_cpu_has_native_bf16", lambda: False)
    assert base.fast_precision("auto", "cpu") is False
    with pytest.raises(ValueError, match="unknown precision"):
        base.fast_precision("fp16", "cpu")


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
