"""``--precision auto`` (splitcam.recon.precision): measured once per device model and torch
version, remembered in the cache, read back without measuring; CPUs without native bfloat16
never measured; a damaged or unwritable cache only means measuring again."""

from __future__ import annotations

import json

import pytest
import torch

import splitcam.recon.precision as precision


@pytest.fixture
def fresh(tmp_path, monkeypatch):
    monkeypatch.setenv(precision.CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(precision, "_MEMO", {})
    calls = []

    def fake_measure(device, **_):
        calls.append(str(device))
        return precision.PrecisionChoice(True, "bfloat16 faster (fake)", 2.0, 1.0)

    monkeypatch.setattr(precision, "measure", fake_measure)
    monkeypatch.setattr(precision, "_cpu_flags", lambda: {"avx512_bf16"})
    return tmp_path, calls


def test_a_choice_is_measured_once_and_read_back_from_the_cache(fresh, monkeypatch):
    tmp, calls = fresh
    first = precision.choose_precision("cpu")
    assert first.fast and calls == ["cpu"]
    data = json.loads((tmp / "precision.json").read_text())
    key = precision.device_key(torch.device("cpu"))
    assert data[key]["fast"] is True and data[key]["bf16_s"] == 1.0 and "measured" in data[key]
    monkeypatch.setattr(precision, "_MEMO", {})  # a new process: from the file, no measuring
    again = precision.choose_precision("cpu")
    assert again == first and calls == ["cpu"]
    assert key.endswith(f"torch {torch.__version__}")


def test_a_cpu_without_native_bfloat16_is_never_measured(fresh, monkeypatch):
    tmp, calls = fresh
    monkeypatch.setattr(precision, "_cpu_flags", lambda: {"avx2"})
    choice = precision.choose_precision("cpu")
    assert not choice.fast and "no native bfloat16" in choice.reason and calls == []
    assert not (tmp / "precision.json").exists()


def test_a_damaged_cache_means_measuring_again(fresh):
    tmp, calls = fresh
    (tmp / "precision.json").write_text("{not json")
    assert precision.choose_precision("cpu").fast and calls == ["cpu"]
    assert json.loads((tmp / "precision.json").read_text())  # rewritten whole


def test_an_unwritable_cache_still_gives_a_choice(fresh, monkeypatch):
    tmp, calls = fresh
    blocked = tmp / "file"
    blocked.write_text("x")
    monkeypatch.setenv(precision.CACHE_ENV, str(blocked / "below-a-file"))
    assert precision.choose_precision("cpu").fast and calls == ["cpu"]


def test_a_choice_of_an_earlier_method_is_measured_again(fresh):
    tmp, calls = fresh
    key = precision.device_key(torch.device("cpu"))
    # Remembered by the first method (no "method" kept): float32 timed with TensorFloat-32 on.
    old = {"fast": False, "reason": "float32 (old)", "fp32_s": 1.0, "bf16_s": 1.1}
    (tmp / "precision.json").write_text(json.dumps({key: old}))
    assert precision.choose_precision("cpu").fast and calls == ["cpu"]
    assert json.loads((tmp / "precision.json").read_text())[key]["method"] == precision.METHOD


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_float32_is_timed_without_tensorfloat32_and_the_switches_come_back(monkeypatch):
    # Each timed step reads the clock: record TensorFloat-32's switch as it is then.
    seen, clock = [], precision.time.perf_counter

    def spy() -> float:
        seen.append(torch.backends.cudnn.allow_tf32)
        return clock()

    monkeypatch.setattr(precision.time, "perf_counter", spy)
    monkeypatch.setattr(torch.backends.cudnn, "allow_tf32", True)
    choice = precision.measure("cuda", steps=1, batch=2)
    # The float32 arm ran without it, the bfloat16 arm as it was, and it is as it was after.
    assert seen[:2] == [False, False] and seen[2:] == [True, True]
    assert torch.backends.cudnn.allow_tf32 and choice.fp32_s is not None
