"""The models shipped in splitcam/weights: each loads, matches its JSON, beats its LMMSE and is
right at every image border."""

from __future__ import annotations

import json

import pytest
import torch

from splitcam import patterns
from splitcam.evaluation.protocol import mean_psnr
from splitcam.io import weights as io_weights
from splitcam.recon.loading import load_model, model_names, model_serves_any_pattern
from splitcam.recon.registry import build_method, model_domain


def _one_pattern_models() -> list[str]:
    """Shipped sRGB models of one pattern, the paper's protocol (a model for any pattern and
    the models trained on photons in linear light have tests of their own)."""
    return [
        name
        for name in model_names()
        if not model_serves_any_pattern(name) and model_domain(name) == "srgb"
    ]


def _photon_models() -> list[str]:
    """Shipped models trained on photons in linear light (model.md §11, 13)."""
    return [name for name in model_names() if model_domain(name) == "linear"]


#: The photon networks checked in the default suite: one behind a filter array, one behind a
#: router. The others (and a network for any sensor, checked on every sensor it trained on) are
#: ``slow``: each costs about 3.5 s, and ``.ci/run`` runs them all.
_PHOTON_QUICK = {"bayer-photon", "router-zou-photon"}


def _photon_cases() -> list:
    """:func:`_photon_models`, those outside :data:`_PHOTON_QUICK` marked slow."""
    return [
        name if name in _PHOTON_QUICK else pytest.param(name, marks=pytest.mark.slow)
        for name in _photon_models()
    ]


@pytest.mark.parametrize("name", _one_pattern_models())
def test_every_shipped_model_loads_matches_its_json_and_beats_its_lmmse(name, shared_data):
    """The models inside the package itself (not a fixture's): at most 2 MB, the JSON's pattern
    and architecture are what loads, deterministic, and better than the training-free closed-form
    LMMSE of the same kernels on crops of held-out training images (ones the models never saw).

    Four 128x128 centre crops, not one: on a single 96x96 crop of busy texture the first C
    network (whose pattern pools each cell's light, so fine detail is gone before any network
    sees it) lost to its LMMSE by 0.7 dB. Over these four the smallest lead is B's, 2.17 / 2.10
    dB at σ 0 / 15; C's is 4.05 / 3.86 since its retraining on every image edge (the first C,
    which knew one edge only, led by 0.64 / 0.75 and would fail the 1 dB margin asserted here;
    docs/results/edges/; 2026-11-25)."""
    import numpy as np

    from splitcam.data.imageio import read_image
    from splitcam.data.patches import list_images
    from splitcam.data.testsets import centre_crop
    from splitcam.patterns import Pattern
    from splitcam.recon.closed_form import closed_form_lmmse

    weights = io_weights.MODELS_DIR / f"{name}.safetensors"
    stored = json.loads((io_weights.MODELS_DIR / f"{name}.json").read_text())
    assert weights.stat().st_size <= 2 * 1024**2
    system = load_model(name)
    meta = system.meta
    assert meta["name"] == name and meta["network"] == stored["network"]
    pattern = Pattern.from_dict(stored["pattern"])
    np.testing.assert_allclose(system.pattern.kernels, pattern.kernels, atol=1e-6)
    segments = meta["provenance"]["segments"]
    assert meta["provenance"]["total_steps"] == sum(s["steps"] for s in segments)
    # a run continued on one schedule has several segments; a fine-tuning adds its own budget,
    # in steps or, where the last segment had a time limit, in minutes of training, which it
    # may stop short of (universal's GPU segment: 7.0 of 10 minutes) but never exceeds by more
    # than the step under way when the time ran out (D's CPU relay cool-down: 8 s steps, 6 s over)
    limit = stored["config"]["run"].get("time_limit")
    if limit:
        last = segments[-1]
        step = last["train_seconds"] / last["steps"]
        assert 0 < last["train_seconds"] <= 60 * limit + step + 1
    else:
        assert meta["provenance"]["total_steps"] >= stored["config"]["optim"]["steps"]

    # The last 32 training images by name are held out of every shipped run's training set.
    crops = [
        (path.name, centre_crop(torch.from_numpy(read_image(path)).permute(2, 0, 1), 128))
        for path in list_images(shared_data / "train")[-4:]
    ]
    method = build_method(name, precision="fp32")
    raw = torch.rand(1, 1, 24, 24, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        assert torch.equal(method.reconstruct(raw, 5.0), method.reconstruct(raw, 5.0))
    net = mean_psnr(method, crops, [0.0, 15.0])
    lmmse = mean_psnr(closed_form_lmmse(pattern), crops, [0.0, 15.0])
    assert net[0.0] > lmmse[0.0] + 1.0 and net[15.0] > lmmse[15.0] + 1.0, (net, lmmse)


#: The lead (dB) the shipped universal model must keep over each library pattern's LMMSE on the
#: test's crops: measured 2.20 (A, sigma 0) to 6.33 (E, sigma 0) for the shipped model, less a
#: margin.
UNIVERSAL_LEAD = 1.5


@pytest.mark.slow  # about 6 s: every library pattern
@pytest.mark.skipif("universal" not in model_names(), reason="no universal model shipped")
def test_the_shipped_universal_model_beats_the_lmmse_of_every_library_pattern(shared_data):
    """The model for any pattern: a few MB, and on held-out crops with odd sides (127 px: every
    period above 1 ends part-way) better than the closed-form LMMSE of each library pattern it
    was trained with (its config's mix) by at least UNIVERSAL_LEAD dB at sigma 0 and 15. On
    patterns it never saw it is not always ahead at sigma 0 (rgbw: -0.05 dB on whole photos,
    docs/results/universal/README.md), so those are measured there, not asserted here."""
    from splitcam.data.imageio import read_image
    from splitcam.data.patches import list_images
    from splitcam.data.testsets import centre_crop
    from splitcam.recon.closed_form import closed_form_lmmse

    weights = io_weights.MODELS_DIR / "universal.safetensors"
    assert weights.stat().st_size <= 4 * 1024**2
    crops = [
        (
            path.name,
            centre_crop(torch.from_numpy(read_image(path)).permute(2, 0, 1), 127, multiple=1),
        )
        for path in list_images(shared_data / "train")[-4:]
    ]
    meta = load_model("universal").meta
    for name in meta["config"]["pattern"]["mix"]:
        method = build_method("universal", pattern=name, precision="fp32")
        assert method.name == f"net-universal-{name}"
        net = mean_psnr(method, crops, [0.0, 15.0])
        lmmse = mean_psnr(closed_form_lmmse(patterns.get(name)), crops, [0.0, 15.0])
        lead = min(net[0.0] - lmmse[0.0], net[15.0] - lmmse[15.0])
        assert lead > UNIVERSAL_LEAD, (name, net, lmmse)


#: Largest border loss allowed (dB): the PSNR with a 4-pixel border left out minus the PSNR of
#: the whole image (issue "every shipped network right at every image edge").
BORDER_LOSS = 0.2


@pytest.mark.slow  # about 10 s a model on 2 cores: CI runs it (-m slow), with the data folder
@pytest.mark.parametrize("name", _one_pattern_models())
def test_every_shipped_model_is_right_at_every_image_border(name, shared_data):
    """On held-out training photos (never trained on) whole (481x321 or 321x481: odd sides) and
    cut to sides that end 2 pixels past a whole period, no shipped network loses more than
    BORDER_LOSS dB at the border, at sigma 0 and 15: the PSNR with a 4-pixel border left out
    exceeds the whole-image PSNR by at most that (means over the photos, as
    docs/results/border/ measures on 12). The photo's own borders count in both, so a network
    trained on whole periods only, which reconstructs a last partial period badly, fails here
    (before its retraining A-opt lost 6.45 dB at sigma 0)."""
    from splitcam.data.images import read_image
    from splitcam.data.patches import list_images
    from splitcam.evaluation.protocol import score, simulate_and_reconstruct
    from splitcam.physics.sensor import SplitterSensor

    method = build_method(name)
    sensor = SplitterSensor(method.pattern)
    ph, pw = method.pattern.period
    photos = []
    for path in list_images(shared_data / "train")[-6:]:
        rgb = torch.from_numpy(read_image(path)).permute(2, 0, 1).contiguous()
        h, w = rgb.shape[-2:]
        hh, ww = (h - 2) // ph * ph + 2, (w - 2) // pw * pw + 2  # 2 past a whole period
        photos += [(path.stem, rgb), (f"{path.stem}-2", rgb[:, :hh, :ww])]
    losses = {}
    for sigma in (0.0, 15.0):
        whole, inner = [], []
        for image, rgb in photos:
            pred = simulate_and_reconstruct(method, sensor, image, rgb, sigma)
            whole.append(score(pred, rgb)["psnr"])
            inner.append(score(pred, rgb, crop=4)["psnr"])
        losses[sigma] = (sum(inner) - sum(whole)) / len(photos)
    assert max(losses.values()) <= BORDER_LOSS, f"{name}: border loss {losses} dB"


#: The lead (dB) every shipped photon network must keep over the linear closed-form LMMSE of each
#: sensor it was trained for, on the test's crops at 30 and 300 photo-electrons.
PHOTON_LEAD = 1.0


@pytest.mark.parametrize("name", _photon_cases())
def test_every_shipped_photon_network_loads_by_name_and_beats_the_linear_lmmse(name, shared_data):
    """A network trained under the photon model in linear light loads by its name, says so
    (linear domain, photon noise in its config), and on held-out crops with odd sides beats the
    closed-form linear LMMSE of every sensor it was trained for by PHOTON_LEAD dB at N = 30 and
    300 (read noise 2 e-); on two whole held-out photos (481x321: odd sides) it is right at the
    border (the PSNR with a 4-pixel border left out exceeds the whole photo's by at most
    BORDER_LOSS dB; measured at most 0.014 dB for bayer, router-zou and A)."""
    from splitcam.data.imageio import read_image
    from splitcam.data.patches import list_images
    from splitcam.data.testsets import centre_crop
    from splitcam.evaluation.protocol import score, score_images
    from splitcam.physics.noise import Exposure
    from splitcam.recon.closed_form import closed_form_lmmse

    meta = load_model(name).meta
    config = meta["config"]
    assert config["data"]["domain"] == "linear" and config["noise"]["model"] == "photon"
    assert (io_weights.MODELS_DIR / f"{name}.safetensors").stat().st_size <= 4 * 1024**2
    paths = list_images(shared_data / "train")[-4:]
    photos = [(p.name, torch.from_numpy(read_image(p)).permute(2, 0, 1)) for p in paths]
    crops = [(n, centre_crop(rgb, 127, multiple=1)) for n, rgb in photos]
    levels = [Exposure(30.0), Exposure(300.0)]
    # A network for any sensor is checked on each it trained on; a sensor's own network on it
    # (its config also lists a mix, unused: it once went to build_method, which ignored it).
    own = config["pattern"]["name"]
    sensors = config["pattern"]["mix"] if own == "random" else [meta["pattern"]["name"]]
    for sensor in sensors:
        method = build_method(name, pattern=sensor, precision="fp32")
        assert method.domain == "linear"
        net = mean_psnr(method, crops, levels, domain="linear")
        lmmse = mean_psnr(
            closed_form_lmmse(patterns.get(sensor), domain="linear"), crops, levels, domain="linear"
        )
        for lv in levels:
            assert net[lv] > lmmse[lv] + PHOTON_LEAD, (name, sensor, lv, net[lv], lmmse[lv])
        loss = [
            score(pred, dict(photos)[image], crop=4)["psnr"] - scores["psnr"]
            for image, _, pred, scores in score_images(
                method, photos[:2], [Exposure(300.0)], domain="linear"
            )
        ]
        assert sum(loss) / len(loss) <= BORDER_LOSS, (name, sensor, loss)
