"""``splitcam study exposure``: filters against splitters at equal light."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from splitcam.cli import main
from splitcam.evaluation.tables import CSV_NAME, read_rows


@pytest.mark.slow
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


def test_study_exposure_cli(tmp_path, capsys) -> None:
    from splitcam.cli import main

    assert (
        main(
            [
                "study",
                "exposure",
                "--max-images",
                "1",
                "--photons",
                "3",
                "300",
                "--patterns",
                "D,bayer",
                "--out",
                str(tmp_path),
                "--quiet",
            ]
        )
        == 0
    )
    text = (tmp_path / "exposure.md").read_text()
    assert "| D |" in text and "Crossover" in text and "Raw SNR" in text
    assert (tmp_path / "exposure.png").is_file()
    data = json_load(tmp_path / "exposure.json")
    assert data["results"]["D"]["300"]["psnr"] > data["results"]["D"]["3"]["psnr"]
    assert main(["study", "exposure", "--photons", "-1", "--out", str(tmp_path)]) == 1
    assert "photons" in capsys.readouterr().err


def json_load(path):
    import json

    return json.loads(path.read_text())


def test_study_breakeven_cli(tmp_path) -> None:
    args = ["study", "breakeven", "--max-images", "1", "--crop", "32", "--photons", "3", "300"]
    args += ["--eta", "0.5", "1", "--chi", "0", "0.6", "--quiet", "--out", str(tmp_path)]
    assert main(args) == 0
    data = json_load(tmp_path / "breakeven.json")
    assert data["reference"] == "rgbw" and data["domain"] == "linear"
    assert [c["verdict"] for c in data["cells"]][-1] == "infeasible"  # 1 + 0.6 > 1
    assert (tmp_path / "breakeven.png").is_file()
    assert "| 1 |" in (tmp_path / "breakeven.md").read_text()


def test_study_exposure_states_crossovers_against_rgbw(tmp_path) -> None:
    args = ["study", "exposure", "--max-images", "1", "--crop", "32", "--photons", "3", "300"]
    assert main([*args, "--patterns", "A,bayer,rgbw", "--quiet", "--out", str(tmp_path)]) == 0
    assert "vs rgbw: PSNR" in (tmp_path / "exposure.md").read_text()
    # --reference names the crossover columns; the same folder's scores are reused.
    patterns = ["--patterns", "A,bayer,rgbw,rgbw-d5100", "--quiet", "--out", str(tmp_path)]
    assert main([*args, *patterns, "--reference", "rgbw,rgbw-d5100"]) == 0
    text = (tmp_path / "exposure.md").read_text()
    assert "vs rgbw-d5100: PSNR" in text and "vs bayer: PSNR" not in text


def test_study_breakeven_with_a_network_for_any_pattern(tmp_path, capsys) -> None:
    """--model: the map's sensors are all reconstructed by one network for any pattern (its
    name on the map and in the JSON); a network of one pattern cannot draw a map."""
    args = ["study", "breakeven", "--max-images", "1", "--crop", "32", "--photons", "10", "1000"]
    args += ["--eta", "0.6", "0.8", "--chi", "0", "0.2", "--quiet"]
    assert main([*args, "--model", "universal-photon", "--out", str(tmp_path)]) == 0
    data = json_load(tmp_path / "breakeven.json")
    assert data["method"] == "net-universal-photon"
    assert all(c["difference"] is not None for c in data["cells"])
    assert "Net-universal-photon of each sensor" in (tmp_path / "breakeven.md").read_text()
    assert main([*args, "--model", "A-photon", "--out", str(tmp_path / "x")]) == 1
    assert "a model for any pattern" in capsys.readouterr().err


def test_study_exposure_with_networks_continues_and_compares_network_with_network(
    tmp_path,
) -> None:
    """Networks beside the LMMSE: the sensors' own network against rgbw's; a second run with
    the same --out reuses every score (its per_image.csv is unchanged)."""
    args = ["study", "exposure", "--max-images", "1", "--crop", "32", "--photons", "10", "1000"]
    args += ["--patterns", "A,bayer,rgbw", "--model", "universal-photon", "--quiet"]
    assert main([*args, "--out", str(tmp_path)]) == 0
    csv = (tmp_path / "evaluation" / "per_image.csv").read_text()
    assert csv.count("net-universal-photon-A") == 2  # one image, two exposures
    text = (tmp_path / "exposure.md").read_text()
    nets = text.split("(networks, each against the reference's network)")[1]
    assert "| net-universal-photon-A |" in nets
    assert main([*args, "--out", str(tmp_path)]) == 0
    assert (tmp_path / "evaluation" / "per_image.csv").read_text() == csv


def test_study_exposure_gives_crossovers_per_scene_set(tmp_path) -> None:
    """Two image folders: the crossovers pooled and for each folder apart, each with its
    interval, in exposure.md and exposure.json."""
    from PIL import Image

    rng = np.random.default_rng(0)
    for folder in ("city", "forest"):
        (tmp_path / folder).mkdir()
        for i in range(2):
            pixels = (rng.random((40, 40, 3)) * 255).astype(np.uint8)
            Image.fromarray(pixels).save(tmp_path / folder / f"{folder}{i}.png")
    data = f"{tmp_path / 'city'},{tmp_path / 'forest'}"
    args = ["study", "exposure", "--datasets", data, "--crop", "32", "--photons", "3", "300"]
    args += ["--patterns", "A,rgbw", "--reference", "rgbw", "--pitch", "0.8", "--quiet"]
    assert main([*args, "--out", str(tmp_path / "o")]) == 0
    text = (tmp_path / "o" / "exposure.md").read_text()
    assert ", city only" in text and ", forest only" in text
    records = json_load(tmp_path / "o" / "exposure.json")["crossovers"]
    assert {r["scene_set"] for r in records} == {"all", "city", "forest"}
    assert {r["images"] for r in records} == {4, 2}


def test_study_exposure_restart_discards_scores_of_other_weights(tmp_path, capsys) -> None:
    """A folder whose scores were made by another method of the same name is refused (one
    line, naming --restart); with --restart the study starts it afresh."""
    args = ["study", "exposure", "--max-images", "1", "--crop", "32", "--photons", "30"]
    args += ["--patterns", "D", "--quiet", "--out", str(tmp_path)]
    assert main(args) == 0
    meta = tmp_path / "evaluation" / "evaluation.json"
    saved = json.loads(meta.read_text())
    saved["fingerprints"] = {k: "0" * 16 for k in saved["fingerprints"]}  # "other weights"
    meta.write_text(json.dumps(saved))
    capsys.readouterr()
    assert main(args) == 1
    assert "--restart" in capsys.readouterr().err
    assert main([*args, "--restart"]) == 0
    assert json.loads(meta.read_text())["fingerprints"] != saved["fingerprints"]
    assert main(["study", "breakeven", "--restart", "--out", str(tmp_path / "b")]) == 1
    assert "--restart is for study exposure" in capsys.readouterr().err


def test_study_exposure_update_scores_again_only_the_changed_method(tmp_path, capsys) -> None:
    """--update: the method whose weights changed since (here its fingerprint, as a model
    shipped since) is scored again, every other method's scores are kept as they are (one of
    them marked, to show it was not recomputed); without it the folder is refused, naming
    --update."""
    args = ["study", "exposure", "--max-images", "1", "--crop", "32", "--photons", "30", "300"]
    args += ["--patterns", "D,A", "--quiet", "--out", str(tmp_path)]
    assert main(args) == 0
    folder = tmp_path / "evaluation"
    first = {(r.method, r.level): r.psnr for r in read_rows(folder / CSV_NAME)}
    meta = folder / "evaluation.json"
    saved = json.loads(meta.read_text())
    changed = next(k for k in saved["fingerprints"] if "lmmse-D" in k)
    now = saved["fingerprints"][changed]
    saved["fingerprints"][changed] = "0" * 16  # "other weights" under lmmse-D's name
    meta.write_text(json.dumps(saved))
    table = folder / CSV_NAME
    with table.open(newline="") as f:
        rows = list(csv.DictReader(f))
    for row in rows:  # lmmse-A's scores marked: kept rows keep the mark
        if row["method"] == "lmmse-A":
            row["psnr"] = "99.0"
    with table.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    capsys.readouterr()
    assert main(args) == 1
    assert "--update" in capsys.readouterr().err
    assert main([*args, "--update"]) == 0
    after = {(r.method, r.level): r.psnr for r in read_rows(table)}
    assert set(after) == set(first)
    for (name, level), psnr in after.items():
        if name == "lmmse-A":
            assert psnr == 99.0  # kept, not scored again
        else:
            assert psnr == pytest.approx(first[name, level], abs=1e-6)  # scored again
    assert json.loads(meta.read_text())["fingerprints"][changed] == now
    assert main(["study", "breakeven", "--update", "--out", str(tmp_path / "b")]) == 1
    assert "--update is for study exposure" in capsys.readouterr().err
