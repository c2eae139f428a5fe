"""The committed results of ``splitcam reproduce`` (docs/results/reproduce) are what the code
computes now: a few of their rows recomputed from scratch, for the methods that are cheap to
run (classical demosaicking and the LMMSE) at a border image and a middle one. A method whose
output changes without its fingerprint changing leaves old rows behind that resume keeps: this
fails then (Malvar's rows once outlived a fix of its image edges by a day)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from splitcam.data.testsets import load_images
from splitcam.evaluation.protocol import score, simulate_and_reconstruct
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.registry import build_method

ROWS = Path(__file__).resolve().parents[2] / "docs/results/reproduce/evaluation/per_image.csv"


@pytest.mark.parametrize(
    ("spec", "method", "image", "sigma"),
    [("malvar2004", "bayer+malvar2004", "kodim01", 10), ("lmmse", "lmmse-bayer", "kodim02", 5)],
)
def test_reproduce_rows_are_what_the_code_computes(shared_data, spec, method, image, sigma):
    rows = {
        (r["method"], r["dataset"], r["image"], r["sigma"]): r
        for r in csv.DictReader(ROWS.open(encoding="utf-8"))
    }
    stored = rows[(method, "kodak24", image, str(sigma))]
    reconstructor = build_method(spec, pattern="bayer")
    assert reconstructor.name == method
    rgb = dict(load_images("kodak24", root=shared_data))[image]
    pred = simulate_and_reconstruct(
        reconstructor, SplitterSensor(reconstructor.pattern), image, rgb, float(sigma)
    )
    assert score(pred, rgb)["psnr"] == pytest.approx(float(stored["psnr"]), abs=1e-6)
