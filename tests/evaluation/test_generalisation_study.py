"""studies/colour/generalisation.py: the two sets of photos (held out, and trained on, never the
same photo), the gap and its bootstrap interval against their definitions, and the table's
cells against the protocol's own mean PSNR."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import load_script, odd_photos

STUDY = Path(__file__).resolve().parents[2] / "studies" / "colour" / "generalisation.py"


def _study():
    return load_script(STUDY, "generalisation_study")


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> Path:
    """40 small photos of odd sides: the recipes' split holds out a tenth of them (the training
    folder's 432 hold out 32), 36 to train on."""
    return odd_photos(tmp_path_factory.mktemp("photos"), 40, (23, 31), seed=3)


def test_the_sets_are_the_recipes_held_out_photos_and_photos_it_trains_on(photos):
    from splitcam.recon.loading import load_model
    from splitcam.training.config import TrainConfig
    from splitcam.training.validation import held_out

    config = load_model("bayer").meta["config"]
    sets = _study().photo_sets(config, photos, 3)
    settings = TrainConfig.from_saved(config).override({"data.train": str(photos)})
    every_held = held_out(settings)
    assert len(every_held) == 4
    assert sets["held out"] == every_held[:3]
    assert not set(sets["trained on"]) & set(every_held)
    # Spaced evenly through the 36 it trains on.
    trained = sorted(set(photos.glob("*.png")) - set(every_held))
    assert len(trained) == 36
    assert sets["trained on"] == [trained[0], trained[12], trained[24]]


def test_the_gap_is_the_difference_of_mean_gains_and_moves_with_them():
    study = _study()
    rng = np.random.default_rng(0)
    held, trained = rng.normal(5.0, 1.0, 20), rng.normal(6.0, 1.0, 24)
    mean, low, high = study.gap(trained, held)
    assert mean == pytest.approx(trained.mean() - held.mean())
    assert low < mean < high
    # The interval against the normal approximation of a difference of two means: about
    # 1.645 standard errors on either side.
    error = np.sqrt(trained.var(ddof=1) / 24 + held.var(ddof=1) / 20)
    assert (high - low) / 2 == pytest.approx(1.645 * error, rel=0.15)
    # Shifting every gain on the photos trained on shifts the gap and its interval by as much.
    moved = study.gap(trained + 0.7, held)
    assert moved == pytest.approx((mean + 0.7, low + 0.7, high + 0.7))
    # A network that does on unseen photos what it does on its own: no gap, and an interval
    # that holds 0.
    same = study.gap(held, held.copy())
    assert same[0] == pytest.approx(0.0) and same[1] < 0 < same[2]
    # Wider spread over the photos, wider interval.
    wide = study.gap(trained * 3, held * 3)
    assert wide[2] - wide[1] > 2.5 * (high - low)


def test_the_table_gives_each_sets_network_and_lmmse_scores(photos, tmp_path):
    from splitcam.data.imageio import decode_image
    from splitcam.data.patches import downscaled
    from splitcam.evaluation.protocol import mean_psnr
    from splitcam.recon.registry import build_method

    study = _study()
    out = tmp_path / "gap.md"
    study.main(["bayer", "--photos", "3", "--sizes", "1", "--data", str(photos), "--out", str(out)])
    row = next(line for line in out.read_text().splitlines() if line.startswith("| bayer |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[:2] == ["bayer", "1"]
    held_net, held_lmmse, held_gain, net, lmmse, gain = (float(c) for c in cells[2:8])
    assert held_gain == pytest.approx(held_net - held_lmmse, abs=0.011)
    assert gain == pytest.approx(net - lmmse, abs=0.011)
    assert float(cells[8].split()[0]) == pytest.approx(gain - held_gain, abs=0.011)
    from splitcam.recon.loading import load_model
    from splitcam.training.config import TrainConfig
    from splitcam.training.validation import held_out

    settings = TrainConfig.from_saved(load_model("bayer").meta["config"]).override(
        {"data.train": str(photos)}
    )
    images = [(p.stem, downscaled(decode_image(p), 1.0)) for p in held_out(settings)[:3]]
    for spec, pattern, cell in (("bayer", None, held_net), ("lmmse", "bayer", held_lmmse)):
        method = build_method(spec, pattern=pattern, precision="fp32", domain="srgb")
        assert mean_psnr(method, images, [0.0])[0.0] == pytest.approx(cell, abs=0.006)
