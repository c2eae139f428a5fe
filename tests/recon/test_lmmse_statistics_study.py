"""studies/colour/lmmse_statistics.py: the copies' statistics are those of the shipped photos'
list, and a network's LMMSE is solved from the statistics it is handed."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from conftest import blocky_images, load_script

from splitcam.recon.closed_form import ImageStatistics, shipped_image_statistics

STUDY = Path(__file__).resolve().parents[2] / "studies" / "colour" / "lmmse_statistics.py"


def _study():
    return load_script(STUDY, "lmmse_statistics_study")


def test_copies_of_another_list_of_photos_than_the_shipped_statistics_are_refused(tmp_path):
    folder = blocky_images(tmp_path / "train", 40)
    with pytest.raises(SystemExit, match="8 photos outside the held-out 32; the shipped"):
        _study().moved_statistics(str(folder), tmp_path / "moved")
    assert not (tmp_path / "moved.json").exists()


def test_the_mixture_reaches_the_closed_form_and_the_network_alike():
    study = _study()
    photos = shipped_image_statistics()
    half = photos.mixed(
        ImageStatistics(photos.mean.flip(0), photos.second.flip(0, 1), photos.count), 0.5
    )
    lmmse = study.reconstructor("D", half, network=False)
    torch.testing.assert_close(lmmse.statistics.statistics.second, half.second)
    net = study.reconstructor("D", half, network=True).network
    torch.testing.assert_close(net.stat_second.double(), half.second)
    torch.testing.assert_close(net.stat_mean.double(), half.mean)


@pytest.mark.slow  # 432 photos written and their statistics estimated twice: about 5 s
def test_statistics_at_a_smaller_size_are_of_the_same_photos_at_that_size(tmp_path):
    """--sizes: size 1 is the shipped statistics; another is estimated on the shipped list of
    photos kept at that size (here from a folder of as many, 96x96), once, then read back."""
    from splitcam.data.patches import ImageCache, list_images
    from splitcam.recon.closed_form import estimate_image_statistics

    folder = blocky_images(tmp_path / "train", 432, blocks=12)  # 96x96
    study = _study()
    assert study.sized_statistics(str(folder), 1.0, tmp_path / "one") is shipped_image_statistics()
    half = study.sized_statistics(str(folder), 0.5, tmp_path / "size-0.5")
    assert half.info["size"] == 0.5 and half.info["images"] == 400
    cache = ImageCache(list_images(folder)[:400], min_size=34, scales=[0.5], progress=False)
    expected = estimate_image_statistics([cache.image(i) for i in range(400)], max_offset=16)
    assert [cache.image(0).shape[-1]] == [48]
    torch.testing.assert_close(half.second, expected.second)
    # Read from its file the second time, not estimated again (the size's dot is no suffix).
    study.estimate_image_statistics = None  # fails if called
    again = study.sized_statistics(str(folder), 0.5, tmp_path / "size-0.5")
    torch.testing.assert_close(again.second, half.second)


def test_sizes_are_one_or_several_joined_by_a_plus():
    import argparse

    sizes = _study()._sizes
    assert sizes("0.5") == (0.5,) and sizes("1+0.5") == (1.0, 0.5)
    for bad in ("0", "1.5", "half", "1+"):
        with pytest.raises(argparse.ArgumentTypeError):
            sizes(bad)
