"""Linear light (SPEC section 13): the sRGB transfer pair, the linear domain of the evaluation
protocol, of the LMMSE and of the commands, and results of two domains kept apart."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from splitcam import patterns
from splitcam.cli import main
from splitcam.evaluation import evaluate, markdown_tables, summarise
from splitcam.evaluation.protocol import mean_psnr, score_images
from splitcam.evaluation.tables import read_rows
from splitcam.io.tensorfiles import meta_checksum
from splitcam.io.weights import MODELS_DIR
from splitcam.physics import DOMAINS, check_domain, linear_to_srgb, srgb_to_linear
from splitcam.physics.noise import Exposure
from splitcam.recon.base import method_domain
from splitcam.recon.closed_form import (
    ImageStatistics,
    closed_form_lmmse,
    estimate_image_statistics,
    shipped_image_statistics,
)
from splitcam.recon.registry import build_method, build_model, model_domain, trained_domain


def _decode_np(u: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, written out in numpy."""
    return np.where(u <= 0.04045, u / 12.92, ((u + 0.055) / 1.055) ** 2.4)


def _encode_np(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, None)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


# --- the transfer pair ----------------------------------------------------------------------------


def test_decoding_at_the_breakpoint_follows_the_formula() -> None:
    u = torch.tensor([0.0, 0.04045, 0.5, 1.0], dtype=torch.float64)
    lin = srgb_to_linear(u)
    assert lin[0] == 0 and lin[-1] == pytest.approx(1.0, abs=1e-15)
    assert lin[1] == 0.04045 / 12.92  # the straight segment up to and including the break
    assert lin[2] == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4, rel=1e-15)
    above = srgb_to_linear(torch.tensor([0.04045 + 1e-12], dtype=torch.float64))
    assert float(above) == pytest.approx(((0.04045 + 1e-12 + 0.055) / 1.055) ** 2.4, rel=1e-14)
    assert abs(float(above) - 0.04045 / 12.92) < 1e-8  # continuous at the break
    enc = linear_to_srgb(torch.tensor([0.0031308, 0.0031308 + 1e-12], dtype=torch.float64))
    assert float(enc[0]) == pytest.approx(12.92 * 0.0031308, rel=1e-15)
    assert abs(float(enc[1] - enc[0])) < 1e-7


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_transfer_pair_matches_a_numpy_reference_in_any_shape(dtype) -> None:
    gen = torch.Generator().manual_seed(0)
    u = torch.rand(2, 3, 5, 7, generator=gen, dtype=torch.float64).to(dtype)
    tol = {"rtol": 1e-6, "atol": 1e-7} if dtype == torch.float32 else {"rtol": 1e-13, "atol": 0}
    lin = srgb_to_linear(u)
    assert lin.dtype == dtype and lin.shape == u.shape
    np.testing.assert_allclose(lin.numpy(), _decode_np(u.double().numpy()), **tol)
    enc = linear_to_srgb(lin)
    np.testing.assert_allclose(enc.numpy(), _encode_np(lin.double().numpy()), **tol)
    for shape in [(), (4,), (1, 1, 1, 2, 3)]:
        x = torch.full(shape, 0.3, dtype=dtype)
        assert srgb_to_linear(x).shape == shape and linear_to_srgb(x).shape == shape


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_every_8bit_value_round_trips_exactly(dtype) -> None:
    v = torch.arange(256, dtype=dtype)
    back = linear_to_srgb(srgb_to_linear(v / 255)).clamp(0, 1) * 255
    assert torch.equal(back.round(), v)


def test_transfer_pair_is_differentiable_outside_zero_to_one() -> None:
    x = torch.tensor([-0.2, 0.0, 0.002, 0.03, 0.5, 1.3], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(srgb_to_linear, (x,))
    assert torch.autograd.gradcheck(linear_to_srgb, (x,))
    out = linear_to_srgb(torch.tensor([-1.0, 2.0])).tolist()
    assert out[0] == pytest.approx(-12.92) and out[1] > 1  # not clipped, never NaN
    with pytest.raises(TypeError, match="floating"):
        srgb_to_linear(torch.arange(3))


def test_check_domain() -> None:
    assert DOMAINS == ("srgb", "linear")
    assert check_domain(" Linear ") == "linear"
    with pytest.raises(ValueError, match="srgb, linear"):
        check_domain("gamma")


# --- the protocol in the linear domain --------------------------------------------------------


class Grey:
    """0.6 of each pixel's raw value as a grey estimate (no 8-bit ties in either domain);
    optionally of a light domain."""

    def __init__(self, name: str = "grey", domain: str | None = None, pattern: str = "bayer"):
        self.name = name
        self.pattern = patterns.get(pattern)
        if domain is not None:
            self.domain = domain
        self.calls = 0
        self.seen: list[torch.Tensor] = []

    def reconstruct(self, raw, sigma):
        self.calls += 1
        self.seen.append(raw.clone())
        return raw.expand(-1, 3, -1, -1) * 0.6


def _image8(h: int = 21, w: int = 26, seed: int = 1) -> tuple[np.ndarray, torch.Tensor]:
    codes = np.random.default_rng(seed).integers(0, 256, size=(3, h, w))
    return codes, torch.from_numpy(codes).float() / 255


def test_linear_protocol_is_decode_sensor_encode_by_hand() -> None:
    """Bayer (one colour per pixel, nothing mixed) and a grey estimate of 0.6 of the raw value:
    the sensor sees each pixel's decoded colour, and every channel of the output is 0.6 of it
    encoded back, rounded to 8 bits and scored against the original codes."""
    codes, rgb = _image8()
    lin = _decode_np(codes / 255)
    mosaic = np.empty(codes.shape[1:])
    for (dy, dx), c in {(0, 0): 0, (0, 1): 1, (1, 0): 1, (1, 1): 2}.items():
        mosaic[dy::2, dx::2] = lin[c, dy::2, dx::2]
    out8 = np.round(np.clip(_encode_np(mosaic * 0.6), 0, 1) * 255)
    mse = np.mean((out8[None] - codes) ** 2)
    by_hand = 10 * np.log10(255**2 / mse)

    method = Grey(domain="linear")
    rows = evaluate([method], [("set", [("im", rgb)])], [0.0], progress=False, domain="linear")
    np.testing.assert_allclose(method.seen[0][0, 0].numpy(), mosaic, rtol=1e-6, atol=1e-7)
    assert rows[0].domain == "linear"
    assert rows[0].psnr == pytest.approx(by_hand, abs=1e-9)
    # In srgb the same method sees the codes / 255 themselves and scales display values.
    srgb = evaluate([Grey()], [("set", [("im", rgb)])], [0.0], progress=False)
    mosaic8 = np.round(np.clip(_encode_np(mosaic), 0, 1) * 255) / 255  # the codes of the mosaic
    out8 = np.round(mosaic8 * 0.6 * 255)
    assert srgb[0].psnr == pytest.approx(10 * np.log10(255**2 / np.mean((out8 - codes) ** 2)))
    assert abs(srgb[0].psnr - by_hand) > 0.5
    assert mean_psnr(Grey(domain="linear"), [("im", rgb)], [0.0], domain="linear") == {
        0.0: pytest.approx(by_hand, abs=1e-9)
    }


def test_a_method_of_another_domain_is_refused() -> None:
    _, rgb = _image8()
    with pytest.raises(ValueError, match=r"grey \(srgb\)"):
        evaluate([Grey()], [("set", [("im", rgb)])], [0.0], progress=False, domain="linear")
    with pytest.raises(ValueError, match=r"grey \(linear\)"):
        evaluate([Grey(domain="linear")], [("set", [("im", rgb)])], [0.0], progress=False)
    with pytest.raises(ValueError, match="light domain"):
        evaluate([Grey()], [("set", [("im", rgb)])], [0.0], progress=False, domain="log")


@pytest.mark.parametrize("domain", DOMAINS)
def test_odd_sized_images_work_in_both_domains(domain) -> None:
    gen = torch.Generator().manual_seed(2)
    smooth = torch.nn.functional.interpolate(
        torch.rand(1, 3, 6, 7, generator=gen), size=(37, 41), mode="bilinear"
    )[0]
    rgb = (smooth * 255).round() / 255
    for pattern in ("D", "bayer"):
        method = build_method("lmmse", pattern=pattern, domain=domain)
        (row,) = evaluate([method], [("s", [("odd", rgb)])], [5.0], progress=False, domain=domain)
        assert row.domain == domain and 15 < row.psnr < 60
        ((_, _, pred, scores),) = score_images(method, [("odd", rgb)], [5.0], domain=domain)
        assert pred.shape == (3, 37, 41) and scores["psnr"] == row.psnr


# --- linear statistics and the methods' domains ------------------------------------------------


def test_shipped_linear_statistics() -> None:
    srgb, linear = shipped_image_statistics(), shipped_image_statistics("linear")
    assert srgb.domain == "srgb" and linear.domain == "linear"
    assert linear.info["images"] == srgb.info["images"] and linear.max_offset == srgb.max_offset
    assert bool((linear.mean < srgb.mean).all())  # decoding darkens mid-tones
    assert shipped_image_statistics("LINEAR") is linear


def test_linear_statistics_are_those_of_the_decoded_images() -> None:
    gen = torch.Generator().manual_seed(4)
    images = torch.rand(2, 3, 20, 22, generator=gen)
    linear = estimate_image_statistics(images, max_offset=3, domain="linear")
    decoded = estimate_image_statistics(srgb_to_linear(images.double()), max_offset=3)
    assert linear.domain == "linear" and decoded.domain == "srgb"
    torch.testing.assert_close(linear.second, decoded.second, rtol=1e-12, atol=1e-15)
    torch.testing.assert_close(linear.mean, decoded.mean, rtol=1e-12, atol=1e-15)


def test_lmmse_and_demosaicking_take_the_domain_asked_for(tmp_path) -> None:
    linear = build_method("lmmse", pattern="D", domain="linear")
    assert method_domain(linear) == "linear" and linear.name == "lmmse-D"
    assert linear.statistics.statistics is shipped_image_statistics("linear")
    assert method_domain(build_method("lmmse", pattern="D")) == "srgb"
    assert method_domain(build_method("malvar2004", domain="linear")) == "linear"
    assert method_domain(build_method("malvar2004")) == "srgb"
    assert method_domain(closed_form_lmmse("A", shipped_image_statistics("linear"))) == "linear"
    with pytest.raises(ValueError, match="statistics of the srgb domain"):
        closed_form_lmmse("A", shipped_image_statistics(), domain="linear")
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


# --- results of both domains in one folder ------------------------------------------------------


def test_results_of_two_domains_are_kept_apart_in_one_folder(tmp_path) -> None:
    _, rgb = _image8()
    images = [("set", [("im", rgb)])]
    levels = [0.0, Exposure(100.0)]
    first = Grey()
    evaluate([first], images, levels, tmp_path, progress=False)
    linear = Grey(domain="linear")
    evaluate([linear], images, levels, tmp_path, progress=False, domain="linear")
    assert first.calls == 2 and linear.calls == 2  # the srgb rows did not count for linear
    rows = read_rows(tmp_path / "per_image.csv")
    assert sorted((r.domain, r.level) for r in rows) == [
        ("linear", "0"),
        ("linear", "N100"),
        ("srgb", "0"),
        ("srgb", "N100"),
    ]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"grey", "grey (linear)"}
    assert summary["grey"]["domain"] == "srgb" and summary["grey (linear)"]["domain"] == "linear"
    assert summary["grey"]["all"]["0"]["psnr"] != summary["grey (linear)"]["all"]["0"]["psnr"]
    table = (tmp_path / "table.md").read_text()
    assert table.startswith("Light domains:") and "| grey (linear) | bayer |" in table
    # Each domain resumes its own rows; the other's stay.
    again, again_linear = Grey(), Grey(domain="linear")
    evaluate([again], images, levels, tmp_path, progress=False)
    evaluate([again_linear], images, levels, tmp_path, progress=False, domain="linear")
    assert again.calls == 0 and again_linear.calls == 0
    assert len(read_rows(tmp_path / "per_image.csv")) == 4
    assert summarise(read_rows(tmp_path / "per_image.csv")) == summary


def test_results_without_a_domain_column_read_as_srgb(tmp_path) -> None:
    path = tmp_path / "per_image.csv"
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000,photons\n"
        "m,D,set,a,0,30.5,0.9,2.0,100\n"
        "m,D,set,b,0,31.5,0.9,2.0\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.domain, row.level, row.psnr) == ("srgb", "N100", 30.5)
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000,photons,domain\n"
        "m,D,set,a,5,30.5,0.9,2.0,0,linear\n"
        "m,D,set,b,5,31.5,0.9,2.0,0,lin\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.domain, row.label) == ("linear", "m (linear)")
    assert markdown_tables({"m": {"pattern": "D", "s": {}}}).startswith("Light domain: srgb")


# --- the commands ---------------------------------------------------------------------------------


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
    assert "bayer+malvar2004 (linear)" in summary and not any(k.startswith("net-") for k in summary)


def test_study_exposure_is_in_linear_light_by_default(tmp_path) -> None:
    args = ["study", "exposure", "--max-images", "1", "--photons", "30", "3000"]
    args += ["--patterns", "D,bayer", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "lin")]) == 0
    assert main([*args, "--domain", "srgb", "--out", str(tmp_path / "srgb")]) == 0
    lin = json.loads((tmp_path / "lin" / "exposure.json").read_text())
    srgb = json.loads((tmp_path / "srgb" / "exposure.json").read_text())
    assert lin["domain"] == "linear" and srgb["domain"] == "srgb"
    assert lin["results"]["D"]["30"]["psnr"] != srgb["results"]["D"]["30"]["psnr"]
    assert "Light domain: linear" in (tmp_path / "lin" / "exposure.md").read_text()
    assert "Light domain: srgb" in (tmp_path / "srgb" / "exposure.md").read_text()


def test_simulate_records_the_domain_and_reconstruct_reads_it(tmp_path, capsys) -> None:
    from PIL import Image

    gen = torch.Generator().manual_seed(5)
    smooth = torch.nn.functional.interpolate(
        torch.rand(1, 3, 4, 5, generator=gen), size=(24, 30), mode="bilinear"
    )[0]
    codes = (smooth * 255).round().numpy()
    Image.fromarray(codes.transpose(1, 2, 0).astype(np.uint8)).save(tmp_path / "im.png")
    raw = tmp_path / "raw.png"
    assert (
        main(
            ["simulate", str(tmp_path / "im.png"), "--pattern", "bayer"]
            + ["--domain", "linear", "--out", str(raw)]
        )
        == 0
    )
    from splitcam.data.imageio import read_raw, read_raw_meta

    assert read_raw_meta(raw)["domain"] == "linear"
    lin = _decode_np(codes / 255)
    np.testing.assert_allclose(read_raw(raw)[0::2, 0::2], lin[0, 0::2, 0::2], atol=2e-4)
    out = tmp_path / "rec.npy"
    rec = ["reconstruct", "--raw", str(raw), "--method", "lmmse", "--out", str(out), "--quiet"]
    assert main(rec) == 0
    assert "(linear domain)" in capsys.readouterr().out
    from_raw = np.load(out)
    image = ["reconstruct", "--image", str(tmp_path / "im.png"), "--method", "lmmse"]
    image += ["--pattern", "bayer", "--domain", "linear", "--out", str(tmp_path / "i.npy")]
    assert main([*image, "--quiet"]) == 0
    np.testing.assert_allclose(np.load(tmp_path / "i.npy"), from_raw, atol=1e-3)
    # Display values out: close to the image, not to its linear radiance.
    error = np.abs(from_raw.transpose(2, 0, 1) - codes / 255).mean()
    assert error < 0.05 < np.abs(from_raw.transpose(2, 0, 1) - lin).mean()
    assert main([*rec, "--domain", "srgb"]) == 1
    assert "contradicts the light domain" in capsys.readouterr().err
    # Files written without the field are of srgb.
    assert main(["simulate", str(tmp_path / "im.png"), "--out", str(tmp_path / "s.png")]) == 0
    assert read_raw_meta(tmp_path / "s.png")["domain"] == "srgb"
