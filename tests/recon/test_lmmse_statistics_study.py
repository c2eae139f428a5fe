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
