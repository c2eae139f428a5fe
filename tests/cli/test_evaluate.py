"""``splitcam evaluate``: methods, test sets, zooms, photon levels, light domains, the main job
and earlier results kept in its folder."""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil

import numpy as np
import pytest
import torch
from conftest import blocky_images, write_photos
from PIL import Image

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation.tables import read_rows
from splitcam.io import weights as io_weights
from splitcam.io.paper import PAPER_PATTERNS
from splitcam.patterns.random import random_pattern
from splitcam.recon.loading import load_model
from splitcam.training.models import export_model


def test_evaluate_draws_the_sigma_chart(tmp_path):
    from splitcam.cli import main

    out = tmp_path / "e"
    args = [
        "evaluate",
        "--method",
        "malvar2004",
        "--max-images",
        "1",
        "--sigmas",
        "0",
        "10",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    assert (out / "sigma_curves.png").stat().st_size > 0
    assert not (out / "zoom").exists()  # a named method draws crops only with --save-images


def test_max_size_scores_the_centre_of_each_image(tmp_path):
    """--max-size cuts every image to its centre (even sizes, whole 2x2 periods); the scores are
    those of the cropped image itself, and the dataset name keeps them apart from whole images."""

    from splitcam.data.testsets import centre_crop, default_images, load_datasets

    rgb = torch.arange(3 * 7 * 9, dtype=torch.float32).reshape(3, 7, 9)
    assert torch.equal(centre_crop(rgb, 4), rgb[:, 1:5, 2:6])
    assert torch.equal(centre_crop(rgb, 100), rgb[:, :6, :8])  # at most the image, even sizes
    ((name, images),) = load_datasets("default", 1, 64)
    assert name == "skimage-64px" and images[0][1].shape == (3, 64, 64)
    whole = default_images()[0][1]
    h, w = whole.shape[-2:]
    top, left = (h - 64) // 2, (w - 64) // 2
    assert torch.equal(images[0][1], whole[:, top : top + 64, left : left + 64])

    out = tmp_path / "e"
    args = [
        "evaluate",
        "--method",
        "bilinear",
        "--max-images",
        "1",
        "--max-size",
        "64",
        "--sigmas",
        "0",
        "--out",
        str(out),
        "--quiet",
    ]
    assert main(args) == 0
    rows = list(csv.DictReader((out / "per_image.csv").open()))
    assert {r["dataset"] for r in rows} == {"skimage-64px"}
    with pytest.raises(ValueError, match="at least 2"):
        load_datasets("default", 1, 1)


def test_evaluate_cli_with_images_and_zoom(tmp_path, capsys):
    folder = write_photos(tmp_path / "photos")
    out = tmp_path / "out"
    assert (
        main(
            [
                "evaluate",
                "--method",
                "bilinear",
                "--method",
                "lmmse",
                "--patterns",
                "D",
                "--datasets",
                str(folder),
                "--sigmas",
                "0",
                "10",
                "--out",
                str(out),
                "--save-images",
                "--quiet",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "| bayer+bilinear | bayer |" in printed and "| lmmse-D | D |" in printed
    assert (out / "images/lmmse-D/photos/img0_sigma10.png").is_file()
    assert (out / "zoom/photos_img0_sigma0.png").is_file()

    def bilinear(out: str, sigmas: list[str], *zooms: str) -> int:
        """`evaluate --method bilinear --save-images` on the folder with these zooms."""
        args = ["evaluate", "--method", "bilinear", "--datasets", str(folder), "--sigmas"]
        args += [*sigmas, "--out", str(tmp_path / out), "--save-images", "--quiet"]
        return main(args + [x for z in zooms for x in ("--zoom", z)])

    assert bilinear("o2", ["0"], "img1:4,6,20") == 0
    assert (tmp_path / "o2/zoom/photos_img1_sigma0.png").is_file()
    assert not (tmp_path / "o2/zoom/photos_img0_sigma0.png").exists()
    # A zoom with its own noise level (the paper's kodim05 at sigma 10, kodim24 at sigma 5):
    # drawn at that level only, each image at its own.
    assert bilinear("o4", ["0", "5", "10"], "img0@10", "img1:4,6,20@5") == 0
    drawn = sorted(p.name for p in (tmp_path / "o4/zoom").glob("*.png"))
    assert drawn == ["photos_img0_sigma10.png", "photos_img1_sigma5.png"]
    assert bilinear("o5", ["0"], "img1@x") == 1
    assert "expected a zoom as IMAGE[:TOP,LEFT,SIZE][@SIGMA]" in capsys.readouterr().err
    assert bilinear("o3", ["0"], "img1:4,x") == 1
    assert "expected a zoom as IMAGE[:TOP,LEFT,SIZE][@SIGMA]" in capsys.readouterr().err
    assert main(["evaluate", "--method", "nonsense", "--datasets", str(folder)]) == 1
    assert "unknown method 'nonsense'" in capsys.readouterr().err


def test_evaluate_cli_photons_in_linear_light(tmp_path, capsys) -> None:
    args = [
        "evaluate",
        "--method",
        "lmmse",
        "--patterns",
        "D,bayer",
        "--datasets",
        "default",
        "--max-images",
        "1",
        "--max-size",
        "64",
        "--photons",
        "100",
        "--quiet",
        "--out",
        str(tmp_path),
    ]
    assert main([*args, "--domain", "linear"]) == 0
    out = capsys.readouterr().out
    assert "Light domain: linear" in out and "lmmse-D (linear)" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"lmmse-D (linear)", "lmmse-bayer (linear)"}
    assert summary["lmmse-D (linear)"]["all"]["N100"]["n_images"] == 1
    assert "Light domain: linear" in (tmp_path / "table.md").read_text()
    assert main([*args, "--lmmse-train", str(tmp_path), "--domain", "linear"]) == 1
    assert "lmmse-train" in capsys.readouterr().err
    assert main([*args, "--model", "D", "--domain", "linear"]) == 1
    assert "trained in the srgb domain" in capsys.readouterr().err


def test_evaluate_main_job_in_linear_light_leaves_srgb_networks_out(tmp_path, capsys) -> None:
    args = ["evaluate", "--domain", "linear", "--max-images", "1", "--max-size", "64"]
    assert main([*args, "--sigmas", "5", "--quiet", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "left out of this linear-domain evaluation" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert {e["domain"] for e in summary.values()} == {"linear"}
    assert "bayer+malvar2004 (linear)" in summary
    # the networks of linear light: every shipped one trained on photons in it, and the one for
    # any pattern for the patterns that no such network of their own serves
    from splitcam.recon.loading import model_names, model_serves_any_pattern
    from splitcam.recon.registry import model_domain

    own = [m for m in model_names() if model_domain(m) == "linear"]
    own = [m for m in own if not model_serves_any_pattern(m)]
    served = {load_model(m).pattern.name for m in own}
    nets = {k.removesuffix(" (linear)") for k in summary if k.startswith("net-")}
    rest = {f"net-universal-photon-{p}" for p in PAPER_PATTERNS if p not in served}
    assert nets == {f"net-{m}" for m in own} | rest and rest


def test_the_main_job_scores_every_shipped_model_on_crops(trained_run, tmp_path, monkeypatch):
    """`splitcam evaluate` with no method named: every shipped model and the baselines, on
    MAIN_JOB_MAX_SIZE centre crops of the built-in photos; `--max-size 0` scores them whole."""

    from splitcam.cli.evaluate import MAIN_JOB_MAX_SIZE

    monkeypatch.setattr(io_weights, "MODELS_DIR", tmp_path / "shipped")
    export_model(trained_run, tmp_path / "shipped" / "D", name="D")
    common = ["--max-images", "1", "--sigmas", "0", "--quiet"]
    assert main(["evaluate", *common, "--out", str(tmp_path / "crops")]) == 0
    rows = list(csv.DictReader((tmp_path / "crops" / "per_image.csv").open()))
    assert {r["dataset"] for r in rows} == {f"skimage-{MAIN_JOB_MAX_SIZE}px"}
    assert {"net-D", "lmmse-D", "bayer+malvar2004"} <= {r["method"] for r in rows}
    assert main(["evaluate", *common, "--max-size", "0", "--out", str(tmp_path / "whole")]) == 0
    rows = list(csv.DictReader((tmp_path / "whole" / "per_image.csv").open()))
    assert {r["dataset"] for r in rows} == {"skimage"}


def json_load(path):
    import json

    return json.loads(path.read_text())


def test_evaluate_photons_cli(tmp_path, capsys) -> None:
    from splitcam.cli import main

    args = [
        "evaluate",
        "--method",
        "lmmse",
        "--method",
        "malvar2004",
        "--patterns",
        "A,bayer",
        "--max-images",
        "1",
        "--quiet",
        "--out",
        str(tmp_path),
    ]
    assert main([*args, "--photons", "20", "2000", "--read-noise", "1.5"]) == 0
    out = capsys.readouterr().out
    assert "N=20 e⁻" in out and "σ=" not in out  # --photons alone: no Gaussian levels
    summary = json_load(tmp_path / "summary.json")
    assert set(summary["bayer+malvar2004"]["all"]) == {"N20", "N2000"}
    assert json_load(tmp_path / "evaluation.json")["photon_sensor"]["read_noise"] == 1.5
    # Photon levels get PSNR against exposure, not an empty chart against sigma.
    assert "exposure_curves.png" in out and not (tmp_path / "sigma_curves.png").exists()
    assert (tmp_path / "exposure_curves.png").stat().st_size > 0
    pixels = np.asarray(Image.open(tmp_path / "exposure_curves.png").convert("L"))
    assert (pixels < 250).mean() > 0.02  # lines and labels drawn, not a blank frame
    assert main([*args, "--photons", "-3"]) == 1
    assert "photons" in capsys.readouterr().err
    # A black level is the ADC's: refused in one line without --gain, recorded with it.
    assert main([*args, "--photons", "20", "--black-level", "64"]) == 1
    assert "give the gain too" in capsys.readouterr().err
    assert main([*args, "--photons", "20", "--gain", "0.5", "--black-level", "64"]) == 0
    sensor = json_load(tmp_path / "evaluation.json")["photon_sensor"]
    assert sensor["black"] == 64 and sensor["gain"] == 0.5


def test_main_job_uses_the_universal_network_for_patterns_without_one(
    tiny_universal, trained_run, tmp_path, capsys, monkeypatch
):
    """`splitcam evaluate --patterns FILE`: a pattern no shipped network serves gets the
    shipped universal network, and the output says so; the shipped networks of other patterns
    are left out (they once all ran)."""

    from splitcam.cli import main
    from splitcam.io import weights
    from splitcam.training.models import export_model

    model, data = tiny_universal
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    for suffix in (".json", ".safetensors"):
        shutil.copy(model.with_suffix(suffix), shipped / f"universal{suffix}")
    export_model(trained_run, shipped / "D", name="D")  # a network of pattern D only
    monkeypatch.setattr(weights, "MODELS_DIR", shipped)
    mine = tmp_path / "mine.toml"
    drawn = random_pattern(np.random.default_rng(5))
    patterns.save(dataclasses.replace(drawn, name="cygm-mine"), mine)
    ev = ["evaluate", "--patterns", str(mine), "--datasets", str(data), "--sigmas", "0"]
    assert main([*ev, "--out", str(tmp_path / "ev"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"pattern {mine} has no shipped network: reconstructed by the universal network" in out
    assert "net-uni-cygm-mine" in out and "lmmse-cygm-mine" in out  # labelled by its own name
    assert f"the main job on {mine}: universal" in out
    summary = json.loads((tmp_path / "ev" / "summary.json").read_text())
    assert not [name for name in summary if "D" in name.split("-")[0]], list(summary)


def test_evaluate_keeps_earlier_results_of_other_methods(tmp_path, capsys):
    """A second evaluation into the same folder used to cut the table to its own rows."""
    import json

    from splitcam.evaluation.tables import CSV_NAME

    data = blocky_images(tmp_path / "img", 2)
    out = tmp_path / "ev"
    common = ["evaluate", "--datasets", str(data), "--out", str(out), "--quiet"]
    assert main([*common, "--method", "lmmse", "--patterns", "D,A", "--sigmas", "0", "5"]) == 0
    first = read_rows(out / CSV_NAME)
    assert len(first) == 2 * 2 * 2
    capsys.readouterr()
    assert main([*common, "--method", "malvar2004", "--sigmas", "0"]) == 0
    printed = capsys.readouterr().out
    rows = read_rows(out / CSV_NAME)
    assert {r.method for r in rows} == {"lmmse-D", "lmmse-A", "bayer+malvar2004"}
    assert len(rows) == len(first) + 2
    assert "keeps the earlier results" in printed and "lmmse-D" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) == {"lmmse-D", "lmmse-A", "bayer+malvar2004"}
    assert "lmmse-A" in (out / "table.md").read_text()
    assert (out / "sigma_curves.png").is_file()  # the table has two levels: the chart too
    # Another border crop cannot share the table: refused, nothing lost.
    assert main([*common, "--method", "bilinear", "--sigmas", "0", "--crop", "4"]) == 1
    assert "--restart" in capsys.readouterr().err
    assert len(read_rows(out / CSV_NAME)) == len(rows)


def test_evaluate_update_scores_again_a_method_of_other_weights(tmp_path, capsys):
    """A folder holding a method's results made with other weights (a model shipped since) is
    refused, naming --update; with it that method is scored again and the others kept."""
    import json

    from splitcam.evaluation.tables import CSV_NAME

    data = blocky_images(tmp_path / "img", 1)
    out = tmp_path / "ev"
    args = ["evaluate", "--datasets", str(data), "--out", str(out), "--quiet", "--sigmas", "0"]
    args += ["--method", "lmmse", "--patterns", "D,A"]
    assert main(args) == 0
    first = {r.method: r.psnr for r in read_rows(out / CSV_NAME)}
    meta = out / "evaluation.json"
    saved = json.loads(meta.read_text())
    now = dict(saved["fingerprints"])
    saved["fingerprints"]["lmmse-D"] = "0" * 16
    meta.write_text(json.dumps(saved))
    capsys.readouterr()
    assert main(args) == 1
    assert "--update" in capsys.readouterr().err
    assert main([*args, "--update"]) == 0
    assert json.loads(meta.read_text())["fingerprints"] == now
    assert {r.method: r.psnr for r in read_rows(out / CSV_NAME)} == pytest.approx(first)


def test_a_tiny_image_in_an_evaluation_folder_is_named(tmp_path, capsys):
    data = blocky_images(tmp_path / "img", 2)
    Image.fromarray(np.zeros((6, 6, 3), np.uint8)).save(data / "tiny.png")
    ev = ["evaluate", "--method", "lmmse", "--patterns", "D", "--datasets", str(data)]
    assert main([*ev, "--out", str(tmp_path / "e")]) == 1
    err = capsys.readouterr().err
    assert "img/tiny (6x6)" in err and "11x11" in err
    assert not (tmp_path / "e" / "per_image.csv").exists()  # refused before any work


def test_evaluate_with_flips_scores_the_ensemble_beside_nothing_else(tmp_path, capsys) -> None:
    """--flips: a network becomes its self-ensemble (labelled +flips); the baselines are
    unchanged, and on the even-sided crop the ensemble's reconstruction is the mean of the
    network's and its transposition's (Bayer's one symmetry there; computed here by hand)."""
    from splitcam.data.testsets import load_datasets
    from splitcam.evaluation.protocol import score, simulate_and_reconstruct
    from splitcam.physics.sensor import SplitterSensor
    from splitcam.recon.registry import build_method

    args = ["evaluate", "--model", "bayer", "--method", "lmmse", "--patterns", "bayer"]
    args += ["--max-images", "1", "--max-size", "33", "--sigmas", "0", "--quiet", "--flips"]
    assert main([*args, "--out", str(tmp_path), "--precision", "fp32"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"net-bayer+flips", "lmmse-bayer"}
    [(_, images)] = load_datasets("default", 1, 33)
    name, rgb = images[0]
    assert rgb.shape[-2:] == (32, 32)
    net = build_method("bayer", precision="fp32")
    sensor = SplitterSensor(net.pattern)
    from splitcam.physics import simulate

    raw = simulate(sensor, rgb[None], name, 0.0)
    with torch.no_grad():
        flipped = net.reconstruct(raw.transpose(-2, -1), 0.0).transpose(-2, -1)
        mean = (net.reconstruct(raw, 0.0) + flipped) / 2
    want = score(mean[0].clamp(0, 1), rgb)["psnr"]
    assert summary["net-bayer+flips"]["all"]["0"]["psnr"] == pytest.approx(want, abs=1e-6)
    plain = score(simulate_and_reconstruct(net, sensor, name, rgb, 0.0), rgb)["psnr"]
    assert want != plain


def test_evaluate_with_flips_gives_a_network_of_any_pattern_all_eight_looks(tmp_path) -> None:
    """--flips all with the universal model on D (no symmetry on even sides): all eight looks,
    each told the flipped pattern; the score is that of their mean, computed here look by look
    with a method built for each transformed pattern. Plain --flips keeps to the exact
    symmetries: on D, the identity alone."""
    from splitcam import patterns
    from splitcam.data.testsets import load_datasets
    from splitcam.evaluation.protocol import score
    from splitcam.physics import simulate
    from splitcam.physics.sensor import SplitterSensor
    from splitcam.recon.ensemble import TRANSFORMS, transformed
    from splitcam.recon.registry import build_method

    args = ["evaluate", "--model", "universal", "--patterns", "D", "--max-images", "1"]
    args += ["--max-size", "33", "--sigmas", "10", "--quiet", "--precision", "fp32"]
    assert main([*args, "--flips", "all", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"net-universal-D+all-flips"}
    [(_, images)] = load_datasets("default", 1, 33)
    name, rgb = images[0]
    d = patterns.get("D")
    raw = simulate(SplitterSensor(d), rgb[None], name, 10.0)
    looks = []
    with torch.no_grad():
        for g in TRANSFORMS:
            method = build_method("universal", pattern=transformed(d, g, 32, 32), precision="fp32")
            looks.append(g.invert(method.reconstruct(g.apply(raw), 10.0)))
    want = score((sum(looks) / 8)[0].clamp(0, 1), rgb)["psnr"]
    got = summary["net-universal-D+all-flips"]["all"]["10"]["psnr"]
    assert got == pytest.approx(want, abs=1e-6)
    plain = score(looks[0][0].clamp(0, 1), rgb)["psnr"]
    assert plain != pytest.approx(want, abs=1e-3)
    assert main([*args, "--flips", "--out", str(tmp_path / "exact")]) == 0
    exact = json.loads((tmp_path / "exact" / "summary.json").read_text())
    assert exact["net-universal-D+flips"]["all"]["10"]["psnr"] == pytest.approx(plain, abs=1e-6)


def test_the_srgb_main_job_leaves_the_photon_networks_out(tmp_path, capsys) -> None:
    """The paper's protocol (srgb, Gaussian noise) scores the shipped sRGB networks; a network
    trained on photons in linear light is named as left out, not run on the wrong light."""
    from splitcam import patterns
    from splitcam.recon.loading import load_model, model_names, model_serves_any_pattern
    from splitcam.recon.registry import model_domain

    def serves_d(m: str) -> bool:
        return model_serves_any_pattern(m) or load_model(m).pattern.equals(patterns.get("D"))

    # The main job on pattern D: the networks that serve D, of which the photon ones are left out.
    linear = [m for m in model_names() if model_domain(m) == "linear" and serves_d(m)]
    if not linear:
        pytest.skip("no photon network shipped")
    args = ["evaluate", "--max-images", "1", "--max-size", "32", "--sigmas", "0", "--quiet"]
    assert main([*args, "--patterns", "D", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"left out of this srgb-domain evaluation: {', '.join(linear)}" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert {e["domain"] for e in summary.values()} == {"srgb"} and "net-D" in summary


def test_each_pattern_named_is_read_once(tmp_path, monkeypatch):
    """``--patterns D`` with the LMMSE and a network for any pattern: one read of ``D``."""
    made = []
    factory = patterns.NAMES["d"]
    monkeypatch.setitem(patterns.NAMES, "d", lambda: made.append(1) or factory())
    folder = tmp_path / "photos"
    folder.mkdir()
    Image.fromarray(np.full((21, 30, 3), 120, np.uint8)).save(folder / "x.png")
    args = ["evaluate", "--method", "lmmse", "--model", "universal", "--patterns", "D"]
    args += ["--datasets", str(folder), "--sigmas", "0", "--quiet", "--out", str(tmp_path / "e")]
    assert main(args) == 0
    assert len(made) == 1


def test_a_copy_of_a_model_beside_it_is_refused_in_one_line_that_says_why(tmp_path, capsys):
    """A user copies a shipped model file to compare it with the shipped one: both are named by
    the name stored inside, so the evaluation refuses before scoring, naming the label twice
    given and where labels come from, and writes nothing."""
    import splitcam.weights

    shipped = splitcam.weights.__path__[0] + "/models/bayer"
    for ext in (".json", ".safetensors"):
        shutil.copy(shipped + ext, tmp_path / f"my-bayer{ext}")
    photos = tmp_path / "photos"
    write_photos(photos, n=1, size=(32, 32))
    out = tmp_path / "out"
    code = main(
        ["evaluate", "--model", "bayer", "--model", str(tmp_path / "my-bayer.json")]
        + ["--datasets", str(photos), "--sigmas", "0", "--out", str(out)]
    )
    err = capsys.readouterr().err
    assert code != 0
    assert "net-bayer more than once" in err and "name stored in its model file" in err
    assert not out.exists()
