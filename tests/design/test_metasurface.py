"""Metasurface design (splitcam.design.metasurface): height maps that raise the closed-form PSNR or
the RGGB collection, and the ``splitcam optics`` files."""

from __future__ import annotations

import numpy as np
import pytest

from splitcam.physics.optics import Optics


def test_design_raises_the_closed_form_psnr_and_the_cli_writes_its_files(tmp_path, capsys):
    from splitcam import patterns
    from splitcam.cli import main
    from splitcam.design import design_metasurface

    small = Optics(pitch=0.5, samples=4, distance=1.0, wavelengths=[450.0, 550.0, 650.0], guard=1)
    result = design_metasurface((2, 2), small, init="random", steps=8, lr=0.2)
    assert np.mean(list(result.psnr_after.values())) > np.mean(list(result.psnr_before.values()))
    assert float(result.height.min()) >= 0 and float(result.height.max()) <= small.max_height
    assert result.pattern.kernels.sum((2, 3)).max() <= 1.0
    out = tmp_path / "router.toml"
    assert (
        main(
            [
                "optics",
                "--profile",
                "lens",
                "--pitch",
                "0.5",
                "--samples",
                "4",
                "--distance",
                "1",
                "--design",
                "--steps",
                "2",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    assert "collection efficiency into RGGB pixels" in capsys.readouterr().out
    assert patterns.load(out).period == (2, 2)
    assert np.load(tmp_path / "router.npy").shape == (8, 8)
    assert (tmp_path / "router.png").is_file() and (tmp_path / "router_height.png").is_file()
    assert main(["optics", "--distance", "-1", "--out", str(out)]) == 1
    assert "distance" in capsys.readouterr().err


def test_routing_design_raises_the_rggb_collection(tmp_path, capsys) -> None:
    from splitcam.cli import main
    from splitcam.design import design_metasurface

    small = Optics(pitch=0.5, samples=4, distance=1.0, wavelengths=[450.0, 550.0, 650.0], guard=1)
    result = design_metasurface((2, 2), small, init="random", steps=15, lr=0.1, objective="routing")
    before, after = np.array(result.collection_before), np.array(result.collection_after)
    assert np.prod(after) ** (1 / 3) > np.prod(before) ** (1 / 3)  # the balanced objective
    assert result.history[-1] > result.history[0]
    assert result.pattern.kernels.sum((2, 3)).max() <= 1.0
    with pytest.raises(ValueError, match="2x2"):
        design_metasurface((1, 3), small, steps=1, objective="routing")
    with pytest.raises(ValueError, match="lmmse or routing"):
        design_metasurface((2, 2), small, steps=1, objective="colour")
    args = [
        "optics",
        "--profile",
        "lens",
        "--pitch",
        "0.5",
        "--samples",
        "4",
        "--distance",
        "1",
        "--design",
        "--objective",
        "routing",
        "--steps",
        "3",
        "--quiet",
        "--out",
        str(tmp_path / "r.toml"),
    ]
    assert main(args) == 0
    assert "collection efficiency into RGGB pixels" in capsys.readouterr().out
