"""One optical stack for every pixel (splitcam.physics.stack): the curves, their checks, and
what putting a sensor behind them does, against reductions written out here."""

from __future__ import annotations

import json

import colour
import numpy as np
import pytest

from splitcam import patterns
from splitcam.cli import main
from splitcam.patterns.spectral import SpectralPattern, scene_basis
from splitcam.physics.radiometry import Camera, SiliconQE
from splitcam.physics.stack import (
    IRCut,
    OpticalStack,
    SceneLight,
    TabulatedCurve,
    d5100_ir_cut,
    stack_of,
)

GRID = np.arange(400.0, 701.0, 10.0)


def test_the_stack_is_the_product_of_its_curves_and_refuses_bad_ones(tmp_path):
    cut, qe = IRCut(640.0, 15.0), SiliconQE(3.0)
    stack = OpticalStack((cut, qe))
    np.testing.assert_allclose(stack(GRID), cut(GRID) * qe(GRID))
    assert OpticalStack(())(GRID).tolist() == [1.0] * len(GRID)
    with pytest.raises(ValueError, match="must lie within \\[0, 1\\]"):
        TabulatedCurve((400.0, 700.0), (0.5, 1.2), "too bright")
    with pytest.raises(ValueError, match="covers 450-700 nm; a stack curve must cover 400-700"):
        TabulatedCurve((450.0, 700.0), (0.5, 0.5), "short")
    with pytest.raises(ValueError, match="unknown stack element 'glass'; known: silicon, ir-cut"):
        stack_of(["glass"])
    csv = tmp_path / "cut.csv"
    csv.write_text("wavelength_nm,transmission\n380,1\n550,0.9\n720,0.1\n")
    curve = stack_of([str(csv)]).elements[0]
    assert curve(550.0) == pytest.approx(0.9) and curve(635.0) == pytest.approx(0.5)


def test_the_d5100_cut_fitted_to_its_red_channel_tracks_it():
    """Above 590 nm a red filter passes nearly all: the cut times silicon's QE follows the
    camera's red curve there (both scaled to 1 at 590 nm)."""
    cut = d5100_ir_cut()
    assert 630 < cut.edge_nm < 660 and cut.width_nm < 30
    red = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    lams = np.arange(590.0, 661.0, 10.0)
    measured = np.interp(lams, red.wavelengths, red.values[:, 0])
    model = cut(lams) * SiliconQE(3.0)(lams)
    np.testing.assert_allclose(model / model[0], measured / measured[0], atol=0.12)


def test_a_spectral_sensor_behind_the_stack_is_its_reduction_of_the_filtered_spectra():
    stack = stack_of(["silicon", "ir-cut"])
    router = patterns.get("router-best-fullwave")
    spectral = router.metadata["spectral"]
    lams, kernels = np.asarray(spectral["wavelengths"]), np.asarray(spectral["kernels"])
    naive = np.einsum("slhw,l,lc->schw", kernels, stack(lams), scene_basis(lams))
    behind = stack.apply(router)
    np.testing.assert_allclose(behind.kernels, naive, rtol=1e-12, atol=1e-15)
    assert behind.name == router.name and "IR cut" in behind.metadata["stack"]
    assert np.all(behind.kernels <= router.kernels + 1e-12)  # a stack only takes light


def test_an_rgb_sensor_is_scaled_by_the_stacks_mean_over_each_colour():
    stack = stack_of(["silicon", "ir-cut"])
    factors = [float(np.sum(stack(GRID) * scene_basis(GRID)[:, c])) for c in range(3)]
    assert factors[0] < factors[1] < factors[2] <= 1  # deep red is what silicon and cuts lose
    for name in ("bayer", "rgbw", "A"):
        pattern = patterns.get(name)
        behind = stack.apply(pattern)
        for c in range(3):
            np.testing.assert_allclose(behind.kernels[:, c], pattern.kernels[:, c] * factors[c])


def test_measured_filters_keep_their_shape_and_a_flat_stack_scales_them_like_any_pixel():
    """A measured curve holds its camera's stack: under a flat stack (a constant c) the array
    is c times itself, as every other sensor is; under any stack no estimated filter passes
    more than all of the light."""
    half = OpticalStack((TabulatedCurve((400.0, 700.0), (0.5, 0.5), "grey glass"),))
    for name in ("rgbw-d5100", "bayer-d5100"):
        array = patterns.get(name)
        np.testing.assert_allclose(half.apply(array).kernels, 0.5 * array.kernels, atol=1e-12)
    stack = stack_of(["silicon", "ir-cut"])
    rgbw = stack.apply(patterns.get("rgbw-d5100"))
    spectral = np.asarray(rgbw.metadata["spectral"]["kernels"])
    lams = np.asarray(rgbw.metadata["spectral"]["wavelengths"])
    assert np.all(spectral.sum((2, 3)) <= stack(lams)[None] + 1e-12)
    # the W pixel (splitter 0) is the bare pixel behind the stack
    np.testing.assert_allclose(spectral[0, :, 0, 0], stack(lams))


def test_study_exposure_puts_every_sensor_behind_the_stack(tmp_path, capsys):
    args = ["study", "exposure", "--max-images", "1", "--crop", "48", "--photons", "30", "3000"]
    args += ["--patterns", "bayer,router-best-fullwave", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "bare")]) == 0
    assert main([*args, "--stack", "silicon,ir-cut", "--out", str(tmp_path / "cut")]) == 0
    bare = json.loads((tmp_path / "bare" / "exposure.json").read_text())["results"]
    cut = json.loads((tmp_path / "cut" / "exposure.json").read_text())["results"]
    for name in ("lmmse-bayer", "lmmse-router-best-fullwave"):
        key = next(k for k in bare if k.endswith(name.split("-", 1)[1]))
        assert cut[key]["30"]["psnr"] < bare[key]["30"]["psnr"]  # less light, more noise
    assert (
        "Every pixel behind: silicon 3 µm deep × IR cut"
        in (tmp_path / "cut" / "exposure.md").read_text()
    )
    capsys.readouterr()
    for extra, message in [
        (["--stack", "glass"], "unknown stack element 'glass'"),
        (["--stack", "silicon", "--silicon-depth", "3"], "leave --silicon-depth out"),
        (["--stack", "silicon", "--model", "A-photon"], "reconstructs A behind no stack"),
    ]:
        out = tmp_path / "refused"
        assert main([*args, *extra, "--out", str(out)]) == 1
        assert message in capsys.readouterr().err and not out.exists()


def _relit_by_hand(kernels: np.ndarray, lams: np.ndarray, name: str) -> np.ndarray:
    """Mallett & Yuksel's basis reflectances under D65, each colour scaled to sum to 1 (the
    model's unit), then relit: times ``S / D65``, scaled to a peak of 1 over 400-700 nm."""
    from colour.recovery import MSDS_BASIS_FUNCTIONS_sRGB_MALLETT2019 as basis

    def on(sd, nm):
        return np.interp(nm, sd.wavelengths, sd.values)

    table = {"A": "A", "LED": "LED-B3"}[name]  # CIE A; CIE LED-B3, a phosphor white LED
    d65, light = colour.SDS_ILLUMINANTS["D65"], colour.SDS_ILLUMINANTS[table]
    reflect = np.stack([np.interp(lams, basis.wavelengths, basis.values[:, c]) for c in range(3)])
    units = (reflect * on(d65, lams)).sum(axis=1)  # K_c: one unit of colour c under D65
    fine = np.arange(400.0, 700.5, 1.0)
    peak = max(on(light, fine) / on(d65, fine))
    spectra = reflect * on(light, lams) / units[:, None] / peak  # (3, L)
    return np.einsum("slhw,cl->schw", kernels, spectra)


@pytest.mark.parametrize("name", ["A", "LED"])
def test_scenes_lit_by_another_illuminant_are_the_reduction_of_relit_spectra(name):
    light = SceneLight(name)
    router = patterns.get("router-best-fullwave")
    spectral = router.metadata["spectral"]
    lams, kernels = np.asarray(spectral["wavelengths"]), np.asarray(spectral["kernels"])
    relit = OpticalStack((), light).apply(router)
    np.testing.assert_allclose(relit.kernels, _relit_by_hand(kernels, lams, name), rtol=1e-9)
    assert "scenes lit by " + name in relit.metadata["stack"]
    # the light and the stack multiply: a curve and the light in one stack, either order
    stack = stack_of(["silicon", "ir-cut"])
    both = OpticalStack(stack.elements, light).apply(router)
    np.testing.assert_allclose(
        both.kernels, _relit_by_hand(kernels * stack(lams)[None, :, None, None], lams, name)
    )


def test_tungsten_light_is_red_and_a_white_scene_gives_a_bare_pixel_its_share():
    light = SceneLight("A")
    factors = OpticalStack((), light).band_factors()
    assert factors[0] == pytest.approx(1.0, abs=0.4) and factors[0] > 3 * factors[2]
    fine = np.arange(400.0, 700.5, 1.0)
    np.testing.assert_allclose(light(fine).max(), 1.0)
    # the bare pixel: its three colours' kernels, on a 1 nm grid, average to the white share
    bare = SpectralPattern("bare", [[0]], fine, np.ones((1, len(fine), 1, 1))).to_pattern()
    relit = OpticalStack((), light).apply(bare)
    assert float(relit.kernels.sum()) / 3 == pytest.approx(light.white_share(), rel=1e-9)
    assert SceneLight("D65").white_share() == 1.0
    with pytest.raises(ValueError, match="unknown illuminant 'F2'; expected one of D65, A, LED"):
        SceneLight("F2")


def test_the_light_is_never_divided_out_of_a_measured_filter():
    """A camera's measured curve holds its stack, not the scene's light: relit without a
    stack, the array's spectra are its measured curves times the light."""
    light = SceneLight("A")
    array = patterns.get("rgbw-d5100")
    spectral = array.metadata["spectral"]
    lams, kernels = np.asarray(spectral["wavelengths"]), np.asarray(spectral["kernels"])
    relit = OpticalStack((), light).apply(array)
    np.testing.assert_allclose(
        relit.metadata["spectral"]["kernels"], kernels * light(lams)[None, :, None, None]
    )


def test_the_lux_of_relit_scenes_count_the_light_a_white_scene_gives():
    """Under a light whose white gives a bare pixel a share w of N, one lux is N / w."""
    plain = Camera(illuminant="A")
    relit = Camera(illuminant="A", white=0.4)
    assert relit.lux(10.0) == pytest.approx(0.4 * plain.lux(10.0))
    assert "lit by A" in relit.describe() and "lit by" not in plain.describe()
    with pytest.raises(ValueError, match="white must be in"):
        Camera(white=0.0)


def test_study_exposure_lights_the_scenes_with_its_illuminant(tmp_path, capsys):
    args = ["study", "exposure", "--max-images", "1", "--crop", "48", "--photons", "30", "3000"]
    args += ["--patterns", "bayer,rgbw-d5100", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "d65")]) == 0
    assert main([*args, "--illuminant", "A", "--out", str(tmp_path / "a")]) == 0
    d65 = json.loads((tmp_path / "d65" / "exposure.json").read_text())
    tungsten = json.loads((tmp_path / "a" / "exposure.json").read_text())
    # tungsten gives the same N far less blue and green: a noisier image (the LMMSE of each)
    for key in ("bayer", "rgbw-d5100"):
        for n in ("30", "3000"):
            assert tungsten["results"][key][n]["psnr"] < d65["results"][key][n]["psnr"]
    assert tungsten["camera"]["illuminant"] == "A" and "camera" in d65
    assert tungsten["camera"]["white"] == pytest.approx(SceneLight("A").white_share())
    assert "illuminant" not in d65["camera"]  # D65's record as before
    note = (tmp_path / "a" / "exposure.md").read_text()
    assert "Scenes lit by A (white gives a bare pixel 0.384 N)" in note
    capsys.readouterr()
    for extra, message in [
        (["--illuminant", "F2"], "unknown illuminant 'F2'"),
        (["--illuminant", "A", "--model", "A-photon"], "reconstructs A behind no stack"),
    ]:
        out = tmp_path / "refused"
        assert main([*args, *extra, "--out", str(out)]) == 1
        assert message in capsys.readouterr().err and not out.exists()
    out = tmp_path / "map"
    assert main(["study", "breakeven", "--illuminant", "A", "--out", str(out)]) == 1
    assert "--illuminant relights them in study exposure only" in capsys.readouterr().err
    assert not out.exists()


def test_a_network_trained_behind_the_stack_is_scored_only_behind_it(tmp_path, capsys):
    """`train --stack` trains on the sensor the exposure study simulates behind that stack (the
    same kernels), and the study takes a network only behind the stack its run recorded: a
    network of the bare sensor would otherwise be scored on another sensor than the study's."""
    from conftest import TINY_SETTINGS, blocky_images, experiment_file

    from splitcam.io import checkpoints as ckpt_io

    photos = blocky_images(tmp_path / "photos", 6)
    config = experiment_file(tmp_path, "tiny", **TINY_SETTINGS)
    train = ["train", "--config", str(config), "--data", str(photos), "--pattern", "rgbw-d5100"]
    train += ["--noise", "photon", "--domain", "linear", "--photons", "10", "1000", "--quiet"]
    stacked, bare = tmp_path / "stacked", tmp_path / "bare"
    assert main([*train, "--stack", "silicon,ir-cut", "--out", str(stacked)]) == 0
    assert main([*train, "--out", str(bare)]) == 0
    want = stack_of("silicon,ir-cut").apply(patterns.get("rgbw-d5100"))
    held = patterns.Pattern.from_dict(ckpt_io.load(stacked).meta["pattern"])
    np.testing.assert_allclose(held.kernels, want.kernels, rtol=0, atol=1e-6)
    assert not np.allclose(held.kernels, patterns.get("rgbw-d5100").kernels, atol=1e-3)
    # resumed, the run keeps the stacked sensor it recorded
    assert main(["train", "--out", str(stacked), "--resume", "--steps", "8", "--quiet"]) == 0
    held = patterns.Pattern.from_dict(ckpt_io.load(stacked).meta["pattern"])
    np.testing.assert_allclose(held.kernels, want.kernels, rtol=0, atol=1e-6)

    study = ["study", "exposure", "--datasets", str(photos), "--max-images", "1", "--crop", "32"]
    study += ["--photons", "30", "3000", "--patterns", "rgbw-d5100", "--quiet"]
    out = tmp_path / "scored"
    args = [*study, "--stack", "silicon,ir-cut", "--checkpoint", str(stacked), "--out", str(out)]
    assert main(args) == 0
    results = json.loads((out / "exposure.json").read_text())["results"]
    assert set(results) == {"rgbw-d5100", "stacked"}  # the LMMSE and the run's network
    capsys.readouterr()
    for extra, message in [
        (["--checkpoint", str(stacked)], "behind silicon 3 µm deep × IR cut"),
        (["--stack", "silicon,ir-cut", "--checkpoint", str(bare)], "behind no stack"),
        (["--stack", "silicon", "--checkpoint", str(stacked)], "the study puts every sensor"),
    ]:
        refused = tmp_path / "refused"
        assert main([*study, *extra, "--out", str(refused)]) == 1
        assert message in capsys.readouterr().err and not refused.exists()
    # a stack named twice would multiply the light by its curves twice
    with pytest.raises(ValueError, match="behind an optical stack already"):
        stack_of("silicon").apply(want)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"pattern.stack": "glass"}, "unknown stack element 'glass'"),
        ({"pattern.stack": "silicon", "pattern.name": "random"}, "leave it out with"),
        ({"pattern.stack": "silicon", "pattern.learn": True}, "leave it out with"),
    ],
)
def test_a_training_stack_is_checked_before_anything_is_written(tmp_path, changes, message):
    from conftest import blocky_images, tiny_config

    from splitcam.training import ConfigError, train

    config = tiny_config(blocky_images(tmp_path / "photos", 4), tmp_path / "run", **changes)
    with pytest.raises(ConfigError, match=message):
        train(config)
    assert not (tmp_path / "run").exists()
