"""Nothing a user owns is lost or silently misread: outputs never replace inputs, a name that
means two things is refused, the validation split is never one tiny image."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import blocky_images, tiny_config
from PIL import Image

from splitcam.cli import main


def _unchanged(path, arr) -> bool:
    with Image.open(path) as im:
        return np.array_equal(np.asarray(im), arr)


@pytest.mark.parametrize(
    "argv",
    [
        [
            "reconstruct",
            "--method",
            "lmmse",
            "--pattern",
            "D",
            "--image",
            "{photo}",
            "--out",
            "{photo}",
        ],
        ["simulate", "{photo}", "--out", "{photo}"],
        ["simulate", "{photo}", "--out", "{dir}/raw.png", "--preview", "{photo}"],
    ],
)
def test_an_output_never_replaces_an_input(argv, photo, tmp_path, capsys):
    path, arr = photo
    argv = [a.format(photo=path, dir=tmp_path) for a in argv]
    assert main(argv) == 1
    assert "would be overwritten" in capsys.readouterr().err
    assert _unchanged(path, arr)


def test_two_outputs_are_two_files(photo, tmp_path, capsys):
    path, _ = photo
    raw = tmp_path / "raw.png"
    assert main(["simulate", str(path), "--out", str(raw), "--preview", str(raw)]) == 1
    assert "name the same file" in capsys.readouterr().err
    assert not raw.exists()
    # The same file by another path counts too.
    other = tmp_path / "sub" / ".." / "raw.png"
    (tmp_path / "sub").mkdir()
    assert main(["simulate", str(path), "--out", str(raw), "--preview", str(other)]) == 1


def test_a_name_that_is_both_a_shipped_model_and_a_folder_is_refused(
    photo, tmp_path, monkeypatch, capsys
):
    """`--checkpoint D` with ./D a run folder (sweep names them so): an error showing both, and
    each still reachable by its unambiguous name."""
    from splitcam.recon.loading import ModelError, model_names
    from splitcam.recon.registry import build_method

    assert "D" in model_names()
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    with pytest.raises(ModelError, match=r"shipped model D and the run folder ./D"):
        build_method("D")
    path, _ = photo
    args = ["reconstruct", "--image", str(path), "--out", str(tmp_path / "r.png")]
    assert main([*args, "--checkpoint", "D"]) == 1
    err = capsys.readouterr().err
    assert "ambiguous" in err and "--model D" in err and "./D" in err
    assert main([*args, "--model", "D", "--quiet"]) == 0  # the shipped one, by its flag


def test_init_from_an_ambiguous_name_is_refused(tmp_path, monkeypatch):
    from splitcam.training import ConfigError, train

    data = blocky_images(tmp_path / "img", 4)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "D").mkdir()
    config = tiny_config(data, tmp_path / "run", **{"run.init_from": "D", "network.features": 64})
    with pytest.raises(ConfigError, match="ambiguous"):
        train(config, progress=False)


def test_validation_never_uses_an_image_smaller_than_its_crop(tmp_path, caplog):
    """A 16x16 image sorting last would have been the whole validation set."""
    import logging

    from splitcam.training import train
    from splitcam.training.trainer import held_out

    data = blocky_images(tmp_path / "img", 5)
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(data / "zz_tiny.png")
    config = tiny_config(data, tmp_path / "run", **{"data.val_crop": 32, "data.val_split": 1})
    chosen = held_out(config)
    assert [p.name for p in chosen] == ["im4.png"]
    caplog.set_level(logging.INFO, logger="splitcam")
    train(config, progress=True)
    assert "validation: 1 of the last 1 images" in caplog.text and "training: im4" in caplog.text
    # The tiny image is trained on, not lost: the training set is the rest.
    from splitcam.training.trainer import _train_source

    assert {p.name for p in _train_source(config)} == {f"im{i}.png" for i in range(4)} | {
        "zz_tiny.png"
    }
    # Images all smaller than the crop: the largest ones, never the tiny one.
    big = tiny_config(data, tmp_path / "r2", **{"data.val_crop": 64, "data.val_split": 2})
    assert [p.name for p in held_out(big)] == ["im3.png", "im4.png"]


def test_resuming_a_finished_run_with_other_settings_records_nothing(tmp_path, caplog):
    """No step runs, so the run's config, changes and checkpoint stay as they were (an exported
    model would otherwise report a batch size and learning rate it was never trained with)."""
    import json
    import logging

    from splitcam.io import checkpoints as ckpt_io
    from splitcam.training import train

    caplog.set_level(logging.INFO, logger="splitcam")
    data = blocky_images(tmp_path / "img", 5)
    run = tmp_path / "run"
    train(tiny_config(data, run, **{"optim.steps": 3}), progress=False)
    before = {n: (run / n).read_bytes() for n in ("config.json", "checkpoint.safetensors")}
    changed = tiny_config(data, run, **{"optim.steps": 3, "optim.lr": 0.5, "data.batch_size": 2})
    result = train(changed, resume=True, progress=False)
    assert result.step == 3 and "nothing to train" in caplog.text
    assert all((run / n).read_bytes() == b for n, b in before.items())
    assert not (run / "changes.jsonl").exists()
    assert ckpt_io.read_meta(run / "checkpoint.safetensors")["config"]["optim"]["lr"] == 1e-3
    assert json.loads((run / "config.json").read_text())["data"]["batch_size"] == 4
    assert "val_psnr" in result.last_metrics
    # More steps: training continues under the new settings, and that is recorded.
    more = tiny_config(data, run, **{"optim.steps": 4, "optim.lr": 0.5})
    assert train(more, resume=True, progress=False).step == 4
    assert json.loads((run / "config.json").read_text())["optim"]["lr"] == 0.5
    assert (run / "changes.jsonl").exists()


def test_a_run_that_diverges_says_so_and_fails(tmp_path, capsys):
    """`--lr 100` used to end at a loss of 1e19 and report "finished" with exit 0."""
    from splitcam.training import train

    data = blocky_images(tmp_path / "img", 5)
    args = ["train", "--data", str(data), "--patch-size", "16", "--batch-size", "4"]
    args += ["--features", "8", "--blocks", "1", "--val-split", "2", "--val-crop", "32"]
    args += ["--val-every", "10", "--threads", "1", "--quiet"]
    assert main([*args, "--steps", "20", "--lr", "100", "--out", str(tmp_path / "bad")]) == 1
    assert "splitcam train: failed:" in capsys.readouterr().err
    good = train(tiny_config(data, tmp_path / "good", **{"optim.steps": 6}), progress=False)
    assert good.failure is None


def test_the_guard_gives_up_after_halving_the_rate_ten_times(tmp_path):
    from splitcam.training import train
    from splitcam.training.trainer import GUARD_GIVES_UP

    data = blocky_images(tmp_path / "img", 5)
    # A factor below 1 makes every step once the window is full a divergence.
    config = tiny_config(
        data,
        tmp_path / "r",
        **{"optim.steps": 400, "optim.divergence_factor": 1e-9, "run.val_every": 1000},
    )
    result = train(config, progress=False)
    assert result.step < 400
    assert result.failure and f"halved the learning rate {GUARD_GIVES_UP} times" in result.failure


def test_models_export_never_replaces_a_model_unasked(tmp_path, monkeypatch, capsys):
    """As the README showed it, `models export RUN --name D` replaced the shipped model D."""
    from splitcam.io import weights
    from splitcam.training import train

    data = blocky_images(tmp_path / "img", 5)
    run = tmp_path / "run"
    train(tiny_config(data, run, **{"optim.steps": 2}), progress=False)
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    (shipped / "D.json").write_text("{}")
    monkeypatch.setattr(weights, "MODELS_DIR", shipped)
    monkeypatch.chdir(tmp_path)
    assert main(["models", "export", str(run), "--name", "D"]) == 0
    assert (tmp_path / "models" / "D.json").is_file()  # a user folder by default
    assert (shipped / "D.json").read_text() == "{}"
    assert main(["models", "export", str(run), "--name", "D"]) == 1  # exists now
    assert "--force" in capsys.readouterr().err
    assert main(["models", "export", str(run), "--name", "D", "--ship"]) == 1
    assert (shipped / "D.json").read_text() == "{}"
    assert main(["models", "export", str(run), "--name", "D", "--ship", "--force"]) == 0
    from splitcam.recon.loading import load_model

    assert load_model("D").meta["name"] == "D"


def test_an_edited_model_file_is_refused_and_old_files_are_fingerprinted_by_their_fields(
    tmp_path,
):
    """An edited `radius` cost 5.2 dB without an error; now the fields carry a checksum."""
    import json

    from splitcam.io.tensorfiles import meta_checksum
    from splitcam.recon.loading import ModelError, load_model
    from splitcam.recon.registry import build_model
    from splitcam.training import train
    from splitcam.training.models import export_model

    data = blocky_images(tmp_path / "img", 5)
    train(tiny_config(data, tmp_path / "run", **{"optim.steps": 2}), progress=False)
    path = export_model(tmp_path / "run", tmp_path / "m")
    meta = json.loads(path.read_text())
    assert meta["meta_sha256"] == meta_checksum(meta)
    first = build_model(path).fingerprint
    edited = {**meta, "network": {**meta["network"], "radius": 2}}
    path.write_text(json.dumps(edited))
    with pytest.raises(ModelError, match="changed after it was written"):
        load_model(path)
    # A file from before the field checksum: loads, and its fingerprint follows its fields.
    del edited["meta_sha256"]
    path.write_text(json.dumps(edited))
    assert build_model(path).fingerprint != first
    # The shipped files all carry it.
    from splitcam.io.weights import MODELS_DIR

    for shipped in MODELS_DIR.glob("*.json"):
        stored = json.loads(shipped.read_text())
        assert stored["meta_sha256"] == meta_checksum(stored), shipped.name


@pytest.mark.parametrize("suffix", [".png", ".npy"])
def test_raw_files_record_how_they_were_made(photo, tmp_path, capsys, suffix):
    """`simulate` records the pattern and noise; `reconstruct --raw` uses them and refuses a
    contradiction; a raw file without the record needs --sigma and --pattern."""
    import numpy as np

    from splitcam.data.imageio import read_raw, read_raw_meta, write_raw

    path, _ = photo
    raw = tmp_path / f"raw{suffix}"
    assert main(["simulate", str(path), "--pattern", "D", "--sigma", "15", "--out", str(raw)]) == 0
    made = read_raw_meta(raw)
    assert made["sigma"] == 15.0 and made["noise"] == "gaussian"
    assert made["pattern"]["name"] == "D"
    rec = ["reconstruct", "--raw", str(raw), "--out", str(tmp_path / "r.png"), "--quiet"]
    # The recorded sigma and pattern are used: the same result as saying them.
    assert main([*rec, "--method", "lmmse"]) == 0
    with Image.open(tmp_path / "r.png") as im:
        implied = np.asarray(im)
    assert main([*rec, "--method", "lmmse", "--pattern", "D", "--sigma", "15"]) == 0
    with Image.open(tmp_path / "r.png") as im:
        assert np.array_equal(np.asarray(im), implied)
    capsys.readouterr()
    # Contradictions.
    assert main([*rec, "--method", "lmmse", "--sigma", "0"]) == 1
    assert "contradicts the noise level" in capsys.readouterr().err
    assert main([*rec, "--method", "lmmse", "--pattern", "A"]) == 1
    assert "contradicts the pattern" in capsys.readouterr().err
    assert main([*rec, "--model", "E"]) == 1  # a network of another pattern (1x3 period)
    assert "differs from the pattern of E" in capsys.readouterr().err
    # Without a record: both must be given.
    bare = tmp_path / f"bare{suffix}"
    write_raw(bare, read_raw(raw))
    assert read_raw_meta(bare) is None
    bare_rec = ["reconstruct", "--raw", str(bare), "--out", str(tmp_path / "b.png")]
    assert main([*bare_rec, "--method", "lmmse", "--pattern", "D"]) == 1
    assert "--sigma" in capsys.readouterr().err
    assert main([*bare_rec, "--method", "lmmse", "--pattern", "D", "--sigma", "15"]) == 0


def test_evaluate_keeps_earlier_results_of_other_methods(tmp_path, capsys):
    """A second evaluation into the same folder used to cut the table to its own rows."""
    import json

    from splitcam.evaluation.tables import CSV_NAME, read_rows

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


def _full_disk(monkeypatch, after: int = 10):
    """Every file write fails with ENOSPC after ``after`` bytes (a disk that fills mid-write)."""
    import builtins
    import errno
    import io as stdio

    real_open = builtins.open

    def fake_open(file, mode="r", *args, **kwargs):
        handle = real_open(file, mode, *args, **kwargs)
        if "w" in mode or "a" in mode:
            write = handle.write

            def limited(data, _write=write):
                if len(data) > after:
                    _write(data[:after])
                    raise OSError(errno.ENOSPC, "No space left on device")
                return _write(data)

            handle.write = limited
        return handle

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(stdio, "open", fake_open)  # what pathlib's write_bytes/write_text use


def test_a_full_disk_damages_nothing_and_names_the_file(photo, tmp_path, monkeypatch, capsys):
    from splitcam.io import stale_temporaries

    path, arr = photo
    out = tmp_path / "rec.png"
    args = ["reconstruct", "--method", "lmmse", "--pattern", "D", "--image", str(path)]
    assert main([*args, "--out", str(out), "--quiet"]) == 0
    before = out.read_bytes()
    _full_disk(monkeypatch)
    assert main([*args, "--sigma", "10", "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and "No space left" in err[0]
    assert out.read_bytes() == before  # the earlier output is intact
    assert not stale_temporaries(tmp_path)
    # A pattern file and a raw file likewise.
    from splitcam import patterns

    toml = tmp_path / "d.toml"
    monkeypatch.undo()
    patterns.save(patterns.get("D"), toml)
    text = toml.read_text()
    _full_disk(monkeypatch)
    with pytest.raises(OSError, match="d.toml"):
        patterns.save(patterns.get("A"), toml)
    assert toml.read_text() == text
    assert _unchanged(path, arr)


def test_training_on_a_full_disk_fails_in_one_line(tmp_path, monkeypatch, capsys):
    data = blocky_images(tmp_path / "img", 5)
    args = ["train", "--data", str(data), "--patch-size", "16", "--batch-size", "2"]
    args += ["--features", "4", "--blocks", "1", "--val-split", "1", "--steps", "4"]
    args += ["--threads", "1", "--out", str(tmp_path / "run"), "--quiet"]
    _full_disk(monkeypatch, after=5)
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left" in err[0] and str(tmp_path / "run") in err[0]


# --- smaller ones -------------------------------------------------------------------------------


def test_optics_refuse_a_pillar_index_equal_to_the_spacer_and_negative_heights(tmp_path, capsys):
    from splitcam.physics.optics import Optics

    with pytest.raises(ValueError, match="above the spacer"):
        Optics(index=1.0)  # was a ZeroDivisionError in the lens profile
    height = tmp_path / "h.npy"
    np.save(height, -np.ones((2 * 8, 2 * 8)))
    args = ["optics", "--profile", str(height), "--samples", "8", "--out", str(tmp_path / "p.toml")]
    assert main(args) == 1
    assert "heights must lie in [0," in capsys.readouterr().err


def test_a_kernel_too_large_for_the_statistics_says_what_to_do():
    import torch

    from splitcam.recon.closed_form import closed_form_mse

    with pytest.raises(ValueError, match="kernels up to 9x9 work with radius 4"):
        closed_form_mse(torch.full((1, 1, 3, 15, 15), 1 / 300), 0.0)


def test_flags_without_effect_are_refused(tmp_path, capsys):
    data = blocky_images(tmp_path / "img", 3)
    assert main(["train", "--data", str(data), "--photons", "10", "100", "--steps", "1"]) == 1
    assert "--photons: settings of the photon model; add --noise photon" in capsys.readouterr().err
    ev = ["evaluate", "--method", "lmmse", "--patterns", "D", "--datasets", str(data)]
    assert main([*ev, "--read-noise", "3", "--out", str(tmp_path / "e")]) == 1
    assert "no effect without --photons" in capsys.readouterr().err
    assert main(["study", "exposure", "--points", "0", "--datasets", str(data)]) == 1
    assert "--points must be at least 1" in capsys.readouterr().err


def test_a_tiny_image_in_an_evaluation_folder_is_named(tmp_path, capsys):
    data = blocky_images(tmp_path / "img", 2)
    Image.fromarray(np.zeros((6, 6, 3), np.uint8)).save(data / "tiny.png")
    ev = ["evaluate", "--method", "lmmse", "--patterns", "D", "--datasets", str(data)]
    assert main([*ev, "--out", str(tmp_path / "e")]) == 1
    err = capsys.readouterr().err
    assert "img/tiny (6x6)" in err and "11x11" in err
    assert not (tmp_path / "e" / "per_image.csv").exists()  # refused before any work


def test_reconstruct_writes_16_bit_and_float_outputs(photo, tmp_path):
    path, _ = photo
    args = ["reconstruct", "--method", "lmmse", "--pattern", "D", "--image", str(path), "--quiet"]
    assert main([*args, "--out", str(tmp_path / "r.png"), "--bits", "16"]) == 0
    assert (tmp_path / "r.png").read_bytes()[24] == 16  # PNG bit depth
    assert main([*args, "--out", str(tmp_path / "r.tif"), "--bits", "16"]) == 0
    assert main([*args, "--out", str(tmp_path / "r.npy")]) == 0
    rec = np.load(tmp_path / "r.npy")
    assert rec.shape == (10, 12, 3) and rec.dtype == np.float32
    with Image.open(tmp_path / "r.png") as im:
        assert im.size == (12, 10)


def test_patterns_show_a_shipped_models_learned_pattern(tmp_path):
    from splitcam import patterns
    from splitcam.recon.loading import load_model

    out = tmp_path / "a.png"
    assert main(["patterns", "show", "A-opt", "--out", str(out)]) == 0
    assert out.stat().st_size > 1000
    assert main(["patterns", "export", "A-opt", "--out", str(tmp_path / "a.toml")]) == 0
    learned = load_model("A-opt").pattern
    assert np.allclose(patterns.load(tmp_path / "a.toml").kernels, learned.kernels)


def test_report_draws_two_learned_patterns_of_one_name_apart(tmp_path):
    from splitcam.evaluation import evaluate
    from splitcam.evaluation.report import make_report
    from splitcam.physics.sensor import LearnableSplitterSensor

    class Fixed:
        def __init__(self, name, pattern):
            self.name, self.pattern = name, pattern

        def reconstruct(self, raw, sigma):
            return raw.expand(-1, 3, -1, -1) / 4

    import torch

    gen = torch.Generator().manual_seed(0)
    images = [("a", torch.rand(3, 16, 16, generator=gen))]
    for i, folder in enumerate(("one", "two")):
        g = torch.Generator().manual_seed(i)
        learned = LearnableSplitterSensor("D", init="random", generator=g).to_pattern()
        evaluate([Fixed("net", learned)], [("s", images)], [0], tmp_path / folder, progress=False)
    report = make_report([tmp_path / "one", tmp_path / "two"], tmp_path / "rep").read_text()
    assert "patterns/D-learned.png" in report and "patterns/D-learned-2.png" in report
    assert (tmp_path / "rep" / "patterns" / "D-learned-2.png").is_file()


def test_sigma_charts_tell_every_line_apart():
    from splitcam.viz.charts import KIND_STYLES, _palette, method_kind

    colours = _palette(16)
    assert len({str(c) for c in colours}) == 16
    kinds = [method_kind(n) for n in ("net-D", "lmmse-D", "bayer+malvar2004", "res: lmmse-A")]
    assert kinds == ["network", "lmmse", "classical", "lmmse"]
    assert len({str(v) for v in KIND_STYLES.values()}) == 3


def test_two_networks_of_one_pattern_name_get_two_colours(tmp_path, monkeypatch):
    """D-opt and D-opt-random both report the pattern "D-learned": still two colours."""
    from matplotlib.axes import Axes

    from splitcam.viz.charts import sigma_chart

    colours = {}
    plot = Axes.plot

    def spy(self, *args, **kwargs):
        colours[kwargs.get("label")] = str(kwargs.get("color"))
        return plot(self, *args, **kwargs)

    monkeypatch.setattr(Axes, "plot", spy)
    per = {"0": {"psnr": 30.0, "ciede2000": 2.0}, "10": {"psnr": 28.0, "ciede2000": 3.0}}
    curves = [("net-D-opt", per), ("net-D-opt-random", per), ("lmmse-D", per), ("net-D", per)]
    kinds = {"net-D-opt": "D-learned", "net-D-opt-random": "D-learned"}
    sigma_chart(curves, tmp_path / "c.png", patterns_of={**kinds, "lmmse-D": "D", "net-D": "D"})
    assert colours["net-D-opt"] != colours["net-D-opt-random"]
    assert colours["lmmse-D"] == colours["net-D"]  # one pattern, one colour
