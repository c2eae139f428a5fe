"""studies/colour/gap_by_chroma.py: each pixel's chroma bin from the BT.601 colour differences,
and the per-channel and per-bin PSNR of saved reconstructions against a known error."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
from conftest import load_script
from PIL import Image

STUDY = Path(__file__).resolve().parents[2] / "studies" / "colour" / "gap_by_chroma.py"


def _study():
    return load_script(STUDY, "gap_by_chroma_study")


def test_chroma_bins_follow_the_bt601_colour_differences():
    study = _study()
    rgb = torch.rand(3, 7, 9, generator=torch.Generator().manual_seed(0))
    rgb[:, 0, 0] = 0.5  # grey: no chroma
    rgb[:, 0, 1] = torch.tensor([1.0, 0.0, 0.0])  # pure red: |(Cb, Cr)| = 0.528 of full scale
    r, g, b = rgb.double()
    y = 0.299 * r + 0.587 * g + 0.114 * b
    chroma = 255 * torch.hypot((b - y) / 1.772, (r - y) / 1.402)
    expected = sum((chroma >= edge).int() for edge in study.EDGES[1:-1])
    bins = study.chroma_bins(rgb)
    assert np.array_equal(bins, expected.numpy())
    assert bins[0, 0] == 0 and bins[0, 1] == len(study.EDGES) - 2


def test_a_known_error_in_one_channel_gives_its_psnr(tmp_path):
    study = _study()
    rng = np.random.default_rng(1)
    truth = rng.integers(10, 240, size=(13, 11, 3), dtype=np.uint8)  # odd sides
    tests = tmp_path / "mine"
    tests.mkdir()
    Image.fromarray(truth).save(tests / "one.png")
    for method, shift in (("exact", 0), ("red-off", 5)):
        out = tmp_path / "eval" / "images" / method / "mine"
        out.mkdir(parents=True)
        rec = truth.astype(int)
        rec[..., 0] += shift
        Image.fromarray(rec.astype(np.uint8)).save(out / "one_sigma0.png")
    lines = study.describe(tmp_path / "eval", 0.0, 0, str(tests))
    rows = {line.split(" | ")[0].lstrip("| "): line.strip("| ").split(" | ") for line in lines}
    red = 10 * math.log10(255**2 / 25)  # every red value 5 off
    assert [float(v) for v in rows["red-off"][1:4]] == [round(red, 2), math.inf, math.inf]
    filled = [float(v) for v in rows["red-off"][4:] if v]
    assert filled and all(v == round(10 * math.log10(3 * 255**2 / 25), 2) for v in filled)
    assert all(float(v) == math.inf for v in rows["exact"][1:] if v)
