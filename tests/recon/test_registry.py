"""The method registry (splitcam.recon.registry): pattern files, light domains, models for any
pattern."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from conftest import random_images, write_photos

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation import evaluate
from splitcam.io.tensorfiles import meta_checksum
from splitcam.io.weights import MODELS_DIR
from splitcam.patterns.random import random_pattern
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.base import method_domain
from splitcam.recon.closed_form import (
    ImageStatistics,
    closed_form_lmmse,
    estimate_image_statistics,
    shipped_image_statistics,
)
from splitcam.recon.registry import build_method, build_model, model_domain, trained_domain


def test_pattern_file_named_like_a_builtin_is_not_the_builtin(tmp_path, capsys):
    """`patterns export D` writes a file whose pattern is called D; edited, it is another
    pattern: the LMMSE must use its kernels and the label must say it is the file."""
    photos = tmp_path / "photos"
    write_photos(photos, size=(60, 64))
    mine = tmp_path / "mine.toml"
    assert main(["patterns", "export", "D", "--out", str(mine)]) == 0
    same = build_method("lmmse", pattern=mine)
    assert same.name == "lmmse-mine.toml" and same.pattern.equals(patterns.get("D"))
    edited = patterns.get("D")
    kernels = edited.kernels.copy()
    kernels[1, 0] = kernels[0, 0]  # the red deflector no longer deflects
    import dataclasses

    patterns.save(dataclasses.replace(edited, kernels=kernels), mine)
    # No shipped fit applies to the edited kernels: the filters are solved for them in closed form.
    closed = build_method("lmmse", pattern=mine)
    assert closed.name == "lmmse-mine.toml"
    assert np.array_equal(closed.statistics.pattern.kernels, kernels)
    from splitcam.recon.closed_form import closed_form_filters

    w_edited, _ = closed_form_filters(patterns.get(mine), 0.0)
    w_builtin, _ = closed_form_filters(patterns.get("D"), 0.0)
    torch.testing.assert_close(closed.statistics.filters(0.0)[0], w_edited)
    assert not torch.allclose(w_edited, w_builtin, atol=1e-3)
    capsys.readouterr()
    assert (
        main(
            [
                "evaluate",
                "--method",
                "lmmse",
                "--patterns",
                str(mine),
                "--datasets",
                str(photos),
                "--sigmas",
                "0",
                "--out",
                str(tmp_path / "o"),
                "--quiet",
            ]
        )
        == 0
    )


@pytest.mark.slow
def test_an_edited_pattern_file_is_fitted_on_training_photos_as_itself(tmp_path):
    """`--lmmse-train` with a file named like a built-in fits the file's kernels, not the
    built-in's: the two fits reconstruct differently."""
    photos = tmp_path / "photos"
    write_photos(photos, size=(60, 64))
    edited = patterns.get("D")
    kernels = edited.kernels.copy()
    kernels[1, 0] = kernels[0, 0]
    import dataclasses

    mine = tmp_path / "mine.toml"
    patterns.save(dataclasses.replace(edited, kernels=kernels), mine)
    fitted = build_method("lmmse", pattern=mine, lmmse_train=photos)
    assert fitted.name == "lmmse-mine.toml"
    assert np.array_equal(fitted.pattern.kernels, kernels)
    assert np.array_equal(fitted.statistics.pattern.kernels, kernels)
    builtin = build_method("lmmse", pattern="D", lmmse_train=photos)
    assert builtin.name == "lmmse-D"
    rows = evaluate([fitted, builtin], [("p", random_images(1, (40, 44)))], [0], progress=False)
    assert rows[0].psnr != pytest.approx(rows[1].psnr)


def _image8(h: int = 21, w: int = 26, seed: int = 1) -> tuple[np.ndarray, torch.Tensor]:
    codes = np.random.default_rng(seed).integers(0, 256, size=(3, h, w))
    return codes, torch.from_numpy(codes).float() / 255


def test_lmmse_and_demosaicking_take_the_domain_asked_for(tmp_path) -> None:
    linear = build_method("lmmse", pattern="D", domain="linear")
    assert method_domain(linear) == "linear" and linear.name == "lmmse-D"
    assert linear.statistics.statistics is shipped_image_statistics("linear")
    assert method_domain(build_method("lmmse", pattern="D")) == "srgb"
    assert method_domain(build_method("malvar2004", domain="linear")) == "linear"
    assert method_domain(build_method("malvar2004")) == "srgb"
    assert (
        method_domain(closed_form_lmmse(patterns.get("A"), shipped_image_statistics("linear")))
        == "linear"
    )
    with pytest.raises(ValueError, match="statistics of the srgb domain"):
        closed_form_lmmse(patterns.get("A"), shipped_image_statistics(), domain="linear")
    with pytest.raises(ValueError, match="lmmse-train"):
        build_method("lmmse", pattern="D", domain="linear", lmmse_train=tmp_path)
    # The stats file of a domain knows it; a file without the field is of srgb.
    stats = estimate_image_statistics(torch.rand(1, 3, 9, 9), max_offset=2, domain="linear")
    assert ImageStatistics.load(stats.save(tmp_path / "s")).domain == "linear"


def _linear_model(tmp_path):
    """A copy of the shipped model D whose config says it was trained in linear light."""
    meta = json.loads((MODELS_DIR / "D.json").read_text())
    meta["config"].setdefault("data", {})["domain"] = "linear"
    meta["meta_sha256"] = meta_checksum(meta)
    shutil.copy(MODELS_DIR / "D.safetensors", tmp_path / "D-linear.safetensors")
    path = tmp_path / "D-linear.json"
    path.write_text(json.dumps(meta))
    return path


def test_a_network_reconstructs_only_in_its_own_domain(tmp_path) -> None:
    assert trained_domain(None) == "srgb" and trained_domain({"data": {}}) == "srgb"
    assert trained_domain({"data": {"domain": "linear"}}) == "linear"
    assert model_domain("D") == "srgb"
    assert method_domain(build_model("D")) == "srgb"
    with pytest.raises(ValueError, match="trained in the srgb domain.*--domain srgb"):
        build_model("D", domain="linear")
    with pytest.raises(ValueError, match="trained in the srgb domain"):
        build_method("D", domain="linear")
    path = _linear_model(tmp_path)
    assert model_domain(path) == "linear"
    net = build_method(str(path))
    assert method_domain(net) == "linear"
    with pytest.raises(ValueError, match="trained in the linear domain"):
        build_method(str(path), domain="srgb")
    _, rgb = _image8(24, 24)
    (row,) = evaluate([net], [("s", [("im", rgb)])], [5.0], progress=False, domain="linear")
    assert row.domain == "linear" and np.isfinite(row.psnr)
    with pytest.raises(ValueError, match="another light domain"):
        evaluate([net], [("s", [("im", rgb)])], [5.0], progress=False)


def _universal_scene(n: int = 2, h: int = 37, w: int = 43, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, h + 4, w + 4, generator=g)
    return torch.nn.functional.avg_pool2d(x, 5, stride=1)


def test_model_for_any_pattern_needs_a_pattern_and_names_a_bad_file(tiny_universal, tmp_path):
    from splitcam.recon.registry import build_method, build_model

    model, _ = tiny_universal
    with pytest.raises(ValueError, match="reconstructs any pattern"):
        build_model(model)
    missing = tmp_path / "mine.toml"
    with pytest.raises(patterns.PatternError, match="mine.toml"):
        build_model(model, pattern=str(missing))
    # A pattern file: the label is the pattern's own name, the reconstruction that pattern's.
    mine = random_pattern(np.random.default_rng(3))
    patterns.save(mine, tmp_path / "mine.toml")
    method = build_method(str(model), pattern=str(tmp_path / "mine.toml"), precision="fp32")
    assert method.name == f"net-uni-{mine.name}" and method.pattern.equals(mine)
    raw = SplitterSensor(mine)(_universal_scene(1, 21, 19))
    assert method.reconstruct(raw, 5.0).shape == (1, 3, 21, 19)
    other = build_method(str(model), pattern="D", precision="fp32")
    assert other.fingerprint != method.fingerprint


def test_a_run_folder_means_its_best_network(trained_run, tmp_path, capsys):
    """Evaluation and reconstruction of a run folder use the weights of its best validation
    (best.safetensors) and say so, with the step; the latest checkpoint is used when its file is
    given."""
    from splitcam.cli._common import warn_failed_runs
    from splitcam.io import checkpoints as ckpt_io

    run = tmp_path / "run"
    shutil.copytree(trained_run, run)
    latest = ckpt_io.load(run / ckpt_io.CHECKPOINT_NAME)
    tensors = {
        k: v + 0.01 if k.startswith("model/") and v.is_floating_point() else v
        for k, v in latest.tensors.items()
        if k.startswith("model/")
    }
    meta = {**{k: v for k, v in latest.meta.items() if k not in ("format", "version")}}
    meta.update({"step": 1, "best_val": 12.5})
    ckpt_io.save(run / ckpt_io.BEST_NAME, meta, tensors)
    raw = torch.rand(1, 1, 12, 12, generator=torch.Generator().manual_seed(0))

    def estimate(spec):
        return build_method(spec, precision="fp32", tile=None).reconstruct(raw, 5.0)

    from_best = estimate(run / ckpt_io.BEST_NAME)
    from_latest = estimate(run / ckpt_io.CHECKPOINT_NAME)
    assert not torch.equal(from_best, from_latest)
    assert torch.equal(estimate(run), from_best)
    warn_failed_runs([str(run)])
    said = capsys.readouterr().out
    assert "using its best validation, 12.50 dB at step 1" in said
    assert f"step {latest.meta['step']}" in said and "checkpoint.safetensors" in said
    # Without a best file the folder means its latest checkpoint.
    (run / ckpt_io.BEST_NAME).unlink()
    assert torch.equal(estimate(run), from_latest)
