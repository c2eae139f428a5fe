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
