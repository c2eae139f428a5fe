"""The gate (splitcam.training.gate, ``splitcam models gate``): a candidate is scored against the
shipped model of its name on held-out photos at half size, ships exactly when the rule holds on the
numbers its table prints, a copy of the shipped model does not ship (no rise), a worse one does
not, a candidate that is no continuation of its namesake is refused with its reason, and bad
input gets one line."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest
import torch
from conftest import odd_photos
from safetensors.torch import load_file, save_file

from splitcam.cli import main
from splitcam.io.tensorfiles import meta_checksum
from splitcam.io.weights import MODELS_DIR
from splitcam.training.gate import FALL_DB, gate, gate_table, ship


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> Path:
    """14 smooth photos of odd sizes: the last one is the run's validation photo, and with the
    last 12 the gate scores 12 whole photos."""
    return odd_photos(tmp_path_factory.mktemp("photos"), 14, (37, 45), seed=1)


def _candidate(folder: Path, name: str, source: str = "D", scale: float = 1.0) -> Path:
    """A copy of the shipped ``source`` model named ``name``, its last layer scaled by
    ``scale`` (1: the shipped weights bit for bit)."""
    folder.mkdir(parents=True, exist_ok=True)
    tensors = load_file(MODELS_DIR / f"{source}.safetensors")
    last = sorted(k for k in tensors if k.endswith("weight"))[-1]
    tensors[last] = (tensors[last].float() * scale).to(tensors[last].dtype)
    out = folder / f"{name}.safetensors"
    save_file(tensors, out)
    meta = json.loads((MODELS_DIR / f"{source}.json").read_text())
    meta.update(name=name, tensors=out.name, sha256=hashlib.sha256(out.read_bytes()).hexdigest())
    meta["meta_sha256"] = meta_checksum(meta)
    path = folder / f"{name}.json"
    path.write_text(json.dumps(meta))
    return path


def _rows(table: str) -> dict[str, list[str]]:
    rows = {}
    for line in table.splitlines():
        if line.startswith("| ") and not line.startswith("| model"):
            cells = [c.strip() for c in line.strip("|").split("|")]
            rows[cells[0]] = cells
    return rows


def test_gate_decides_by_its_rule_on_the_numbers_it_prints(photos, tmp_path) -> None:
    torch.manual_seed(0)
    same = _candidate(tmp_path / "same", "D")
    worse = _candidate(tmp_path / "worse", "D", scale=1.5)
    verdicts = gate([same, worse], photos, threads=1)
    for verdict in verdicts:
        assert verdict.refused is None and verdict.photos == 12
        assert [float(level) for level in verdict.levels] == [0.0, 15.0]
    identical, degraded = verdicts
    # The shipped weights bit for bit: the same scores, no rise, not shipped.
    assert identical.before == identical.after and not identical.ships
    assert all(c < -FALL_DB for c in degraded.change) and not degraded.ships
    rows = _rows(gate_table(verdicts))
    cells = rows["D"]
    before, after = ([float(v) for v in cells[i].split(" / ")] for i in (3, 4))
    rule = after[0] > before[0] and after[-1] >= before[-1] - FALL_DB
    assert cells[6] == ("yes" if rule else "no") == "no"
    assert [row.split("|")[-2].strip() for row in gate_table(verdicts).splitlines()[-2:]] == [
        str(same),
        str(worse),
    ]  # each row names its file
    ship_to = tmp_path / "models"
    ship_to.mkdir()
    assert ship(verdicts, ship_to) == [] and not any(ship_to.iterdir())


def test_a_passing_candidate_ships_its_pair(photos, tmp_path) -> None:
    """A candidate whose verdict passes is copied with its tensors, and nothing else."""
    path = _candidate(tmp_path / "c", "D")
    (verdict,) = gate([path], photos, threads=1)
    verdict.after = [b + 0.1 for b in verdict.before]  # as a better candidate would score
    assert verdict.ships
    ship_to = tmp_path / "models"
    ship_to.mkdir()
    assert ship([verdict], ship_to) == ["D"]
    assert sorted(p.name for p in ship_to.iterdir()) == ["D.json", "D.safetensors"]
    shipped = (ship_to / "D.safetensors").read_bytes()
    assert shipped == path.with_suffix(".safetensors").read_bytes()


def test_two_passing_candidates_of_one_name_ship_neither(photos, tmp_path) -> None:
    """Shipping both would leave whichever came last, silently: the gate refuses, copies
    nothing, and names the two."""
    from splitcam.training.gate import GateError

    paths = [_candidate(tmp_path / f"c{i}", "D") for i in range(2)]
    verdicts = gate(paths, photos, threads=1)
    for verdict in verdicts:
        verdict.after = [b + 0.1 for b in verdict.before]
    ship_to = tmp_path / "models"
    ship_to.mkdir()
    with pytest.raises(GateError, match="2 candidates for D pass") as caught:
        ship(verdicts, ship_to)
    assert all(str(p) in str(caught.value) for p in paths)
    assert not any(ship_to.iterdir())


def test_refused_candidates_keep_their_reason(photos, tmp_path) -> None:
    # D's network named E: trained from pattern D, while the shipped E started from E.
    wrong = _candidate(tmp_path / "w", "E", source="D")
    unknown = _candidate(tmp_path / "u", "nosuch", source="D")
    verdicts = gate([wrong, unknown], photos, threads=1)
    assert "from pattern D" in verdicts[0].refused and not verdicts[0].ships
    assert "no shipped model" in verdicts[1].refused
    rows = _rows(gate_table(verdicts))
    assert "not gated" in rows["E"][5] and rows["E"][6] == "no"


def test_cli_gate_is_dry_unless_told_and_refuses_bad_input(photos, tmp_path, capsys) -> None:
    path = _candidate(tmp_path / "c", "D")
    table = tmp_path / "gates" / "gate.md"  # its folder made, as --out's are
    assert main(["models", "gate", str(path), "--data", str(photos), "--table", str(table)]) == 0
    out = capsys.readouterr().out
    assert "would ship: nothing" in out and _rows(table.read_text())["D"][6] == "no"
    shutil.copy(path, tmp_path / "D.txt")
    for argv, message in [
        (["models", "gate"], "needs candidates"),
        (["models", "gate", str(tmp_path / "D.txt")], "not an exported model"),
        (["models", "gate", str(path), "--data", str(tmp_path / "none")], "no training photos"),
        (["models", "gate", str(path), "--ship", "--out", str(tmp_path)], "not both"),
        (["models", "gate", str(path), "--data", str(photos), "--table", str(tmp_path)], "folder"),
    ]:
        assert main(argv) != 0
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1


def test_the_gate_scores_each_photo_at_half_size_with_odd_sides() -> None:
    """A 2x2 block mean is what a half-size photo holds (a smooth photo: the antialiased bicubic
    filter then agrees with it to within a few 8-bit levels), and the sides stay odd."""
    from splitcam.training.gate import SCALE, gate_size

    assert SCALE == 0.5
    y, x = torch.meshgrid(torch.arange(41.0), torch.arange(31.0), indexing="ij")
    waves = [0.5 + 0.4 * torch.sin(y / 9 + c) * torch.cos(x / 7) for c in range(3)]
    image = (torch.stack(waves, -1).numpy() * 255).round().astype("uint8")
    assert tuple(gate_size(image).shape) == (3, 19, 15)  # 41x31 -> 20x16 (rounded), less one each
    even = image[:40, :30]
    got = gate_size(even)
    assert got.dtype == torch.float32 and tuple(got.shape) == (3, 19, 15)  # 20x15, less a row
    pixels = torch.from_numpy(even.astype("float32") / 255).permute(2, 0, 1)
    means = pixels.reshape(3, 20, 2, 15, 2).mean(dim=(2, 4))[:, :19]
    assert (got - means).abs().max() < 4 / 255
    sixteen = even.astype("uint16") * 257
    assert torch.allclose(gate_size(sixteen), got, atol=1 / 255)
