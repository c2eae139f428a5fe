"""The evaluation protocol (splitcam.evaluation.protocol): the same noise for every method,
reproducible numbers, result files, resuming, photon levels and the linear light domain."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
import torch
from conftest import Spy, random_images
from PIL import Image

from splitcam import patterns
from splitcam.evaluation import evaluate, summarise
from splitcam.evaluation.metrics import psnr
from splitcam.evaluation.protocol import mean_psnr, score_images
from splitcam.evaluation.tables import read_rows
from splitcam.physics import DOMAINS
from splitcam.physics.noise import Exposure
from splitcam.physics.sensor import SplitterSensor
from splitcam.recon.closed_form import (
    closed_form_lmmse,
)
from splitcam.recon.registry import build_method
from splitcam.training import TrainConfig, train


class Oracle:
    """Knows the answer: PSNR is infinite."""

    def __init__(self, images) -> None:
        self.name = "oracle"
        self.pattern = patterns.get("A")
        self._answers = iter([img[None] for _, img in images for _ in range(2)])

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        return next(self._answers)


def test_every_method_sees_the_same_noise():
    images = random_images()
    a, b, c = Spy("a"), Spy("b"), Spy("c", pattern="A")
    evaluate([a, b, c], [("set", images)], [0, 10], progress=False)
    assert len(a.seen) == 4
    for x, y in zip(a.seen, b.seen, strict=True):
        assert torch.equal(x, y)
    # Another pattern: different raw image, identical noise on top of it.
    for k, (_, img) in enumerate(images):
        for j in range(2):
            i = 2 * k + j
            noise_d = a.seen[i] - SplitterSensor("D")(img[None].double()).float()
            noise_a = c.seen[i] - SplitterSensor("A")(img[None].double()).float()
            torch.testing.assert_close(noise_d, noise_a, rtol=0, atol=1e-6)
    assert torch.equal(a.seen[0], SplitterSensor("D")(images[0][1][None].double()).float())
    assert a.seen[1].std() > 0


def test_results_files_and_infinite_psnr(tmp_path):
    images = random_images()
    rows = evaluate(
        [Oracle(images), Spy("spy")], [("set", images)], [0, 5], tmp_path, progress=False
    )
    assert all(r.psnr == float("inf") for r in rows if r.method == "oracle")
    summary = json.loads((tmp_path / "summary.json").read_text())
    oracle = summary["oracle"]["all"]["5"]
    assert oracle["n_infinite"] == 2 and oracle["n_images"] == 2 and oracle["ssim"] == 1.0
    with open(tmp_path / "per_image.csv") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 8
    spy = [r for r in table if r["method"] == "spy" and r["sigma"] == "5"]
    mean = np.mean([float(r["psnr"]) for r in spy])
    assert summary["spy"]["set"]["5"]["psnr"] == pytest.approx(mean, abs=1e-3)
    md = (tmp_path / "table.md").read_text()
    assert "| oracle | A | inf / 1.0000 | inf / 1.0000 |" in md


def test_psnr_in_rows_is_the_metric_of_the_clamped_output():
    images = random_images(1)
    spy = Spy("spy")
    rows = evaluate([spy], [("set", images)], [0], progress=False)
    guess = (spy.seen[0].expand(-1, 3, -1, -1) / 4)[0].clamp(0, 1)
    assert rows[0].psnr == pytest.approx(psnr(guess, images[0][1]))
    cropped = evaluate([spy], [("set", images)], [0], crop=3, progress=False)
    assert cropped[0].psnr == pytest.approx(psnr(guess, images[0][1], crop=3))
    assert cropped[0].psnr != pytest.approx(rows[0].psnr)


def test_tiny_checkpoint_evaluates_reproducibly(tmp_path):
    folder = tmp_path / "train"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4):
        img = np.kron(rng.random((5, 5, 3)), np.ones((8, 8, 1)))
        Image.fromarray((img * 255).astype(np.uint8)).save(folder / f"t{i}.png")
    cfg = TrainConfig().override(
        {
            "data.train": str(folder),
            "data.patch_size": 16,
            "data.batch_size": 2,
            "network.features": 4,
            "network.blocks": 1,
            "optim.steps": 2,
            "run.out": str(tmp_path / "run"),
            "run.threads": 1,
        }
    )
    train(cfg, progress=False)
    images = random_images(2, size=(16, 18))
    first = evaluate(
        [build_method(tmp_path / "run")], [("s", images)], [0, 10], tmp_path / "e1", progress=False
    )
    second = evaluate(
        [build_method(tmp_path / "run")], [("s", images)], [0, 10], tmp_path / "e2", progress=False
    )
    assert first == second
    assert (tmp_path / "e1/summary.json").read_text() == (tmp_path / "e2/summary.json").read_text()
    assert summarise(first)["run"]["pattern"] == "D"


def _interrupting(name: str, stop_at: int) -> Spy:
    """A Spy that is interrupted (Ctrl-C) on its ``stop_at``-th reconstruction."""
    spy = Spy(name)
    plain = spy.reconstruct

    def reconstruct(raw, sigma):
        if len(spy.seen) + 1 == stop_at:
            raise KeyboardInterrupt
        return plain(raw, sigma)

    spy.reconstruct = reconstruct
    return spy


def test_interrupted_evaluation_keeps_its_rows_and_resumes(tmp_path):
    images = random_images(3)
    whole = evaluate(
        [Spy("a"), Spy("b")], [("set", images)], [0, 10], tmp_path / "whole", progress=False
    )
    out = tmp_path / "part"
    a, b = Spy("a"), _interrupting("b", stop_at=4)
    with pytest.raises(KeyboardInterrupt):
        evaluate([a, b], [("set", images)], [0, 10], out, progress=False)
    with open(out / "per_image.csv") as fh:
        kept = list(csv.DictReader(fh))
    assert len(kept) == len(a.seen) + len(b.seen) == 7  # every finished result is on disk
    a2, b2 = Spy("a"), Spy("b")
    rows = evaluate([a2, b2], [("set", images)], [0, 10], out, progress=False)
    assert len(a2.seen) + len(b2.seen) == 12 - 7  # only the missing ones are computed
    assert sorted(rows, key=lambda r: r.key) == sorted(whole, key=lambda r: r.key)
    assert (out / "summary.json").read_text() == (tmp_path / "whole/summary.json").read_text()
    # Another pattern under the same method name: refused, nothing computed or changed.
    before = (out / "per_image.csv").read_text()
    c = Spy("a", pattern="A")
    with pytest.raises(ValueError, match="under another name"):
        evaluate([c], [("set", images)], [0], out, progress=False)
    assert c.seen == [] and (out / "per_image.csv").read_text() == before
    # Unless its changed results are to be scored again (reproduce --update): only its rows are
    # recomputed, with the new pattern, and the other method's rows stay as they were.
    e = Spy("a", pattern="A")
    rows = evaluate([e], [("set", images)], [0, 10], out, progress=False, rescore_changed=True)
    assert len(e.seen) == 6 and {r.pattern for r in rows} == {"A"}
    with open(out / "per_image.csv") as fh:
        now = list(csv.DictReader(fh))
    was = list(csv.DictReader(io.StringIO(before)))
    b_rows = [r for r in now if r["method"] == "b"]
    assert len(b_rows) == 6 and b_rows == [r for r in was if r["method"] == "b"]
    assert {r["pattern"] for r in now if r["method"] == "a"} == {"A"}
    # --restart recomputes everything.
    d = Spy("a", pattern="A")
    evaluate([d], [("set", images)], [0], out, progress=False, resume=False)
    assert len(d.seen) == 3


class _Intruder(Spy):
    """A method that, at its second image, starts a second evaluation into the same folder."""

    def __init__(self, out, images) -> None:
        super().__init__("a")
        self.out, self.images, self.refusal = out, images, None

    def reconstruct(self, raw, sigma: float):
        if len(self.seen) == 1:
            second = Spy("b")
            with pytest.raises(ValueError) as refused:
                evaluate([second], [("set", self.images)], [0], self.out, progress=False)
            self.refusal = (str(refused.value), len(second.seen))
        return super().reconstruct(raw, sigma)


def test_a_second_evaluation_into_a_folder_in_use_is_refused(tmp_path):
    """Both would continue its per_image.csv and write over each other's rows."""
    images = random_images(3)
    out = tmp_path / "busy"
    first = _Intruder(out, images)
    rows = evaluate([first], [("set", images)], [0], out, progress=False)
    message, computed = first.refusal
    assert message.startswith(f"another evaluation is using {str(out)!r}") and computed == 0
    assert len(rows) == 3 and len(read_rows(out / "per_image.csv")) == 3
    assert not (out / ".lock").exists()  # a results folder keeps only results
    # Released at the end: the next evaluation continues the folder.
    later = Spy("b")
    evaluate([later], [("set", images)], [0], out, progress=False)
    assert len(later.seen) == 3 and len(read_rows(out / "per_image.csv")) == 6


def test_zoom_arguments_are_checked_before_any_work(tmp_path):
    images = random_images(2)
    spy = Spy("a")
    for match, zoom in (
        ("not among the images evaluated", "kodim05"),
        ("lies outside", "img1:30,2,8"),
    ):
        with pytest.raises(ValueError, match=match):
            evaluate(
                [spy], [("set", images)], [0], tmp_path, save_images=True, zoom_images=[zoom],
                progress=False,
            )  # fmt: skip
    with pytest.raises(ValueError, match="finite sigma"):
        evaluate([spy], [("set", images)], [0, float("nan")], tmp_path, progress=False)
    assert spy.seen == []


def _decode_np(u: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, written out in numpy."""
    return np.where(u <= 0.04045, u / 12.92, ((u + 0.055) / 1.055) ** 2.4)


def _encode_np(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, None)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


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


def json_load(path):
    import json

    return json.loads(path.read_text())


def _photos(count: int = 2) -> list[tuple[str, torch.Tensor]]:
    gen = torch.Generator().manual_seed(5)
    small = torch.rand(count, 3, 6, 6, generator=gen)
    big = torch.nn.functional.interpolate(small, size=(36, 40), mode="bilinear")
    return [(f"ph{i}", big[i]) for i in range(count)]


def test_evaluate_at_exposures_scores_what_the_exposure_study_scores(tmp_path) -> None:
    """`evaluate` with Exposures: rows labelled N<photons> beside the Gaussian ones, the same
    numbers as `study exposure` for the same method and images (two paths, one protocol)."""
    from splitcam.evaluation import evaluate
    from splitcam.evaluation.exposure import exposure_study
    from splitcam.evaluation.tables import read_rows

    images = _photos()
    levels = [5.0, Exposure(30.0, read_noise=2.0), Exposure(3000.0, read_noise=2.0)]
    rows = evaluate(
        [closed_form_lmmse(patterns.get("D"))], [("set", images)], levels, tmp_path, progress=False
    )
    assert {r.level for r in rows} == {"5", "N30", "N3000"}
    study = exposure_study(
        images, patterns=[patterns.get("D")], photons=[30.0, 3000.0], progress=False, domain="srgb"
    )
    for n in (30.0, 3000.0):
        mine = [r.psnr for r in rows if r.photons == n]
        assert np.mean(mine) == pytest.approx(study["D"][n]["psnr"], rel=1e-12)
    summary = json_load(tmp_path / "summary.json")
    assert summary["lmmse"]["all"]["N3000"]["psnr"] > summary["lmmse"]["all"]["N30"]["psnr"]
    assert list(summary["lmmse"]["all"]) == ["5", "N30", "N3000"]  # sigmas first
    assert "N=30 e⁻" in (tmp_path / "table.md").read_text()
    assert read_rows(tmp_path / "per_image.csv") == rows


def test_evaluate_resumes_photon_rows_only_under_the_same_sensor(tmp_path) -> None:
    from splitcam.evaluation import evaluate

    class Counter:
        name = "count"
        pattern = __import__("splitcam").patterns.get("D")

        def __init__(self) -> None:
            self.calls = 0

        def reconstruct(self, raw, sigma):
            self.calls += 1
            return raw.expand(-1, 3, -1, -1) / 3

    images = _photos()
    first = Counter()
    evaluate([first], [("s", images)], [0.0, Exposure(100.0)], tmp_path, progress=False)
    assert first.calls == 4
    again = Counter()
    evaluate([again], [("s", images)], [0.0, Exposure(100.0)], tmp_path, progress=False)
    assert again.calls == 0
    other_sensor = Counter()  # another read noise: the photon rows are recomputed, sigma 0 kept
    evaluate(
        [other_sensor],
        [("s", images)],
        [0.0, Exposure(100.0, read_noise=5.0)],
        tmp_path,
        progress=False,
    )
    assert other_sensor.calls == 2
    with pytest.raises(ValueError, match="share their sensor settings"):
        evaluate(
            [Counter()],
            [("s", images)],
            [Exposure(10.0), Exposure(100.0, read_noise=5.0)],
            tmp_path,
            progress=False,
        )


def test_a_second_evaluation_into_the_folder_loses_nothing(tmp_path) -> None:
    """Another sigma, another image set or crop, another method: each run adds its rows and
    replaces only those it recomputes (the README's main job followed by its fifth command
    used to take per_image.csv from 480 rows to 390)."""
    images = random_images(3)
    out = tmp_path / "out"
    evaluate([Spy("a"), Spy("b")], [("set", images)], [0], out, progress=False)
    evaluate([Spy("a")], [("set", images)], [10], out, progress=False)
    crops = [(name, img[:, :16, :16]) for name, img in images]
    evaluate([Spy("a")], [("set-16px", crops)], [0, 10], out, progress=False)
    rows = read_rows(out / "per_image.csv")
    keys = {(r.method, r.dataset, r.level) for r in rows}
    assert len(rows) == 3 * 2 + 3 + 3 * 2 == len({r.key for r in rows})
    assert keys == {
        ("a", "set", "0"),
        ("b", "set", "0"),
        ("a", "set", "10"),
        ("a", "set-16px", "0"),
        ("a", "set-16px", "10"),
    }
    # The same command again computes nothing and keeps everything; a zoom recomputes the
    # rows it draws, and replaces only those.
    again = Spy("a")
    evaluate([again], [("set", images)], [10], out, progress=False)
    assert again.seen == [] and len(read_rows(out / "per_image.csv")) == 15
    zoomed = Spy("a")
    evaluate([zoomed], [("set", images)], [10], out, progress=False, zoom_only=True)
    assert len(zoomed.seen) == 1  # the first image, drawn again
    after = read_rows(out / "per_image.csv")
    assert len(after) == 15 and {(r.method, r.dataset, r.level) for r in after} == keys


def test_whole_photos_and_crops_never_rank_in_one_pool(tmp_path) -> None:
    """A folder of whole photos and 16-px centre crops pools each apart (all-whole, all-16px):
    no "all" that averages a crop with its whole photo, in the summary, table or report."""
    from splitcam.evaluation.report import make_report

    images = random_images(2)
    out = tmp_path / "out"
    evaluate([Spy("a")], [("set", images)], [0, 10], out, progress=False)
    crops = [(name, img[:, :16, :16]) for name, img in images]
    evaluate([Spy("a"), Spy("b")], [("set-16px", crops)], [0, 10], out, progress=False)
    summary = json.loads((out / "summary.json").read_text())
    assert "all" not in summary["a"] and {"all-whole", "all-16px"} <= set(summary["a"])
    assert "all-whole" not in summary["b"] and summary["b"]["all-16px"]["0"]["n_images"] == 2
    whole = [
        r.psnr for r in read_rows(out / "per_image.csv") if r.dataset == "set" and r.level == "0"
    ]
    assert summary["a"]["all-whole"]["0"]["psnr"] == pytest.approx(float(np.mean(whole)))
    assert "### all-16px" in (out / "table.md").read_text()
    with pytest.raises(ValueError, match="cut differently"):
        make_report([out], tmp_path / "report")


def test_a_table_marks_cells_over_other_images() -> None:
    from splitcam.evaluation.tables import EvalRow, markdown_tables

    rows = [EvalRow("a", "D", "set", f"i{i}", 0.0, 30.0, 0.9, 2.0) for i in range(3)]
    rows += [EvalRow("a", "D", "set", "i0", 10.0, 25.0, 0.8, 3.0)]
    table = markdown_tables(summarise(rows))
    assert "(n = 1)" in table and "do not rank" in table


def test_a_failed_evaluation_leaves_no_half_made_folder(tmp_path) -> None:
    """A method that crashes on its first image: the new results folder is not left behind
    holding a header-only CSV. A folder that already held results keeps them."""

    class Broken(Spy):
        def reconstruct(self, raw, sigma):
            raise RuntimeError("broken method")

    images = random_images(2)
    out = tmp_path / "new"
    with pytest.raises(RuntimeError, match="broken"):
        evaluate([Broken("x")], [("set", images)], [0], out, progress=False)
    assert not out.exists()
    kept = tmp_path / "kept"
    evaluate([Spy("a")], [("set", images)], [0], kept, progress=False)
    with pytest.raises(RuntimeError, match="broken"):
        evaluate([Broken("x")], [("set", images)], [0], kept, progress=False)
    assert {r.method for r in read_rows(kept / "per_image.csv")} == {"a"}
