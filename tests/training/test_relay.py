"""The GPU relay (splitcam.training.relay) end to end on the CPU, on tiny settings: a queue of a
fixed-pattern network (D) and one that learns its pattern (A-opt) trained within its minutes,
candidates exported with their provenance, the gate's decision applied as its table says for
both, a candidate that is no continuation of its namesake skipped with its reason, and bad input
refused with one line and nothing changed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from conftest import odd_photos

from splitcam.training.gate import SCALE


def _relay():
    from splitcam.training import relay

    return relay


def _slot_runs(argv: list[str], out: Path, name: str) -> list:
    """The configurations of ``name``'s runs in a relay started with ``argv`` into ``out``
    (nothing trained)."""
    relay = _relay()
    args = relay.parse([*argv, "--out", str(out), "--colour"])
    relay.start_folder(out, args)
    return relay.relay_configs(name, args, out, 1.0)


@pytest.fixture(scope="module")
def photos(tmp_path_factory) -> Path:
    """14 smooth photos of odd sizes (so the held-out ones end part-way through periods), large
    enough for a 64-pixel patch at half size (the shipped D trains on the photos at half size)."""
    return odd_photos(tmp_path_factory.mktemp("photos"), 14, (135, 163), seed=0)


@pytest.fixture(scope="module")
def relayed(photos, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("relay") / "out"
    code = _relay().main(
        [
            "--minutes",
            "0.7",
            "--out",
            str(out),
            "--data",
            str(photos),
            "--queue",
            "D",
            "A-opt",
            "--batch",
            "2",
            "--device",
            "cpu",
            "--precision",
            "fp32",
        ]
    )
    assert code == 0
    return out


@pytest.mark.slow
def test_relay_trains_exports_and_tables_within_its_minutes(relayed) -> None:
    candidate = json.loads((relayed / "candidates" / "D.json").read_text())
    segment = candidate["provenance"]["segments"][-1]
    assert segment["device"].startswith("cpu") and segment["batch_size"] == 2
    assert segment["patches"] == 2 * segment["steps"] > 0
    # The run had its half of the 0.7 minutes, less the first network's assumed overhead.
    assert 0 < segment["train_seconds"] <= 0.35 * 60
    assert candidate["config"]["run"]["init_from"] == "D"
    # The description appends the relay's segment with its own device (a CPU here, not a GPU).
    appended = candidate["description"].rsplit("; then ", 1)[1]
    assert appended.startswith(f"{segment['train_seconds'] / 60:.1f} minutes of training (")
    assert f"{segment['steps']} steps of batch 2, cpu" in appended and "GPU" not in appended
    table = (relayed / "relay.md").read_text()
    assert "| D |" in table and "| A-opt |" in table and "→" in table
    # On a CPU the table says how much of its threads each network had.
    used = _row(table.splitlines(), "D")["CPU used"]
    assert used.endswith(" of its threads") and 0 < float(used.split()[0]) <= 1.5
    assert (relayed / "runs" / "D" / "checkpoint.safetensors").exists()
    # A-opt learns its pattern: it went on learning it from the shipped A-opt's, so the
    # candidate's pattern moved while the pattern both started from is A.
    learned = json.loads((relayed / "candidates" / "A-opt.json").read_text())
    assert learned["start_pattern"]["name"] == "A" and learned["pattern"]["name"] == "A-learned"


def _row(table: list[str], name: str) -> dict[str, str]:
    """The row of model ``name`` in a Markdown gate table, by the table's column names."""

    def cells(row: str) -> list[str]:
        return [c.strip() for c in row.strip().strip("|").split("|")]

    header = next(line for line in table if line.startswith("| model |"))
    row = next(line for line in table if line.startswith(f"| {name} |"))
    return dict(zip(cells(header), cells(row), strict=True))


@pytest.mark.slow
def test_gate_ships_exactly_what_its_table_says(relayed, photos, tmp_path) -> None:
    relay = _relay()
    ship_to = tmp_path / "models"
    ship_to.mkdir()
    args = ["--gate", str(relayed), "--data", str(photos), "--ship-to", str(ship_to)]
    assert relay.main([*args, "--dry-run"]) == 0
    assert not (relayed / "gate.md").exists() and not any(ship_to.iterdir())
    # What the current folder holds at the stage files' paths (a model shipped the same day
    # from the repository's own relay has its stage there), to check the gate leaves it be.
    started = json.loads((relayed / "relay.json").read_text())["started"][:10]
    stages = {name: Path(relay.STAGE_DIR, started, f"{name}.toml") for name in ("D", "A-opt")}
    here = {name: p.read_bytes() if p.exists() else None for name, p in stages.items()}
    assert relay.main(args) == 0
    rows = (relayed / "gate.md").read_text().splitlines()
    for name in ("D", "A-opt"):
        row = _row(rows, name)
        before, after = ([float(v) for v in row[c].split(" / ")] for c in ("shipped", "candidate"))
        ships = after[0] > before[0] and after[-1] >= before[-1] - 0.05
        assert row["ships"] == ("yes" if ships else "no")
        assert row["file"] == str(relayed / "candidates" / f"{name}.json")
        assert (ship_to / f"{name}.json").exists() == ships
        # A shipped model's relay stage lands beside it, never in the current folder.
        stage = stages[name]
        assert (ship_to / stage).exists() == ships
        assert (stage.read_bytes() if stage.exists() else None) == here[name]
        # The run's validation photo (1 of 14 held out: the last) and the last 12, whole.
        assert row["photos"] == "12"


@pytest.mark.slow
def test_bad_input_gets_one_line_and_changes_nothing(relayed, photos, tmp_path, capsys) -> None:
    relay = _relay()
    fresh = tmp_path / "fresh"
    base = ["--data", str(photos), "--device", "cpu"]
    cases = [
        (["--minutes", "1", "--out", str(fresh), "--queue", "nosuch", *base], "unknown model"),
        (["--minutes", "0", "--out", str(fresh), *base], "--minutes must be > 0"),
        (["--minutes", "-2", "--out", str(fresh), *base], "--minutes must be > 0"),
        (["--minutes", "1", "--out", str(relayed), "--queue", "D", *base], "another relay"),
        (["--gate", str(fresh), "--data", str(photos)], "no relay candidates"),
    ]
    for argv, message in cases:
        assert relay.main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
        assert not fresh.exists()
    # A candidate whose pattern is not its shipped model's is skipped with its reason; the
    # other candidates are still gated.
    wrong = tmp_path / "wrong"
    shutil.copytree(relayed, wrong)
    for suffix in (".json", ".safetensors"):
        (wrong / "candidates" / f"D{suffix}").rename(wrong / "candidates" / f"E{suffix}")
    meta = json.loads((wrong / "candidates" / "E.json").read_text())
    meta["tensors"] = "E.safetensors"
    from splitcam.io.tensorfiles import meta_checksum

    meta["meta_sha256"] = meta_checksum(meta)
    (wrong / "candidates" / "E.json").write_text(json.dumps(meta))
    assert relay.main(["--gate", str(wrong), "--data", str(photos), "--dry-run"]) == 0
    out = capsys.readouterr().out
    skipped = _row(out.splitlines(), "E")
    assert "not gated" in skipped["change"] and "from pattern D" in skipped["change"]
    assert skipped["ships"] == "no"
    assert any(line.startswith("| A-opt | 12 |") for line in out.splitlines())
    assert "would ship: " in out and "E" not in out.split("would ship: ")[1]


@pytest.mark.slow
def test_colour_relay_appends_the_colour_stage_and_its_cooldown(photos, tmp_path) -> None:
    relay = _relay()
    out = tmp_path / "colour"
    argv = ["--minutes", "0.5", "--out", str(out), "--data", str(photos), "--queue", "D"]
    argv += ["--batch", "2", "--device", "cpu", "--precision", "fp32", "--colour"]
    assert relay.main(argv) == 0
    candidate = json.loads((out / "candidates" / "D.json").read_text())
    from splitcam.io.weights import MODELS_DIR

    shipped = json.loads((MODELS_DIR / "D.json").read_text())
    before = len(shipped["provenance"]["segments"])
    stage, cooldown = candidate["provenance"]["segments"][before:]
    # The stage shows the colour the photos lack, at the recipe's rate; the cool-down shows the
    # photos alone at half of it, continued from the stage's run.
    assert stage["settings"]["data"]["colour_swap"] == 0.25
    assert stage["settings"]["data"]["colour_chroma"] == 0.25
    assert cooldown["settings"]["data"]["colour_swap"] == 0
    assert cooldown["settings"]["data"]["colour_chroma"] == 0
    assert cooldown["recipe"]["lr"] == pytest.approx(stage["recipe"]["lr"] / 2)
    assert cooldown["init_from"].endswith("D-colour")
    assert stage["steps"] > 0 and cooldown["steps"] > 0
    # Its table row sums both runs.
    row = next(r for r in (out / "relay.md").read_text().splitlines() if r.startswith("| D |"))
    assert int(row.split("|")[2]) == stage["steps"] + cooldown["steps"]
    assert json.loads((out / "relay.json").read_text())["colour"] is True
    # Shipped, it stays its own recipe: each run's stage file is written from what it recorded.
    from splitcam.training import TrainConfig
    from splitcam.training.recipe import shipped_recipe

    root = tmp_path / "repo"
    written = relay.write_stage_files(out / "candidates" / "D.json", root)
    started = json.loads((out / "relay.json").read_text())["started"][:10]
    # (an empty root: the stage of the relay D shipped from is written there too)
    written = [p for p in written if started in p.as_posix()]
    assert [p.relative_to(root).as_posix() for p in written] == [
        f"experiments/gpu/relay/{started}/D-colour.toml",
        f"experiments/gpu/relay/{started}/D.toml",
    ]
    files = [stage.file for stage in shipped_recipe(candidate, "D").stages[-2:]]
    assert files == [p.relative_to(root).as_posix() for p in written]
    colour, cool = (TrainConfig.from_file(p) for p in written)
    assert colour.data.colour_swap == 0.25 and cool.data.colour_swap == 0
    assert cool.optim.lr == pytest.approx(colour.optim.lr / 2)
    assert relay.write_stage_files(out / "candidates" / "D.json", root) == []  # there already


def test_half_size_relay_trains_every_run_on_the_photos_at_half_size(photos, tmp_path) -> None:
    argv = ["--minutes", "1", "--data", str(photos), "--queue", "B", "--device", "cpu"]
    runs = {}
    for flags in ([], ["--half-size"]):
        out = tmp_path / ("half" if flags else "whole")
        runs[bool(flags)] = _slot_runs([*argv, *flags], out, "B")
        assert json.loads((out / "relay.json").read_text())["half_size"] is bool(flags)
    from splitcam.recon.loading import load_model
    from splitcam.training import TrainConfig

    # B's last stage trained on whole photos and halves (D's, since its relay slot, at half size
    # only, like the relay's --half-size: it would not tell the two apart).
    saved = TrainConfig.from_saved(load_model("B").meta["config"]).data
    assert saved.scales != [0.5] and saved.val_scale == 1.0
    shipped = saved.scales
    assert [run.data.scales for run in runs[False]] == [shipped, shipped]
    assert [run.data.scales for run in runs[True]] == [[0.5], [0.5]]
    # Validated at the gate's size where the runs train at half size, else as the recipe did.
    assert [run.data.val_scale for run in runs[True]] == [SCALE, SCALE]
    assert [run.data.val_scale for run in runs[False]] == [1.0, 1.0]


def test_colour_mined_reaches_the_colour_part_only(photos, tmp_path, capsys) -> None:
    """``--colour-mined P --mine-score S`` mines P of the colour part's patches by S, recorded in
    the relay's folder; the cool-down trains on the photos alone; without it the colour part
    mines nothing. Mining without the colour stage, a share outside [0, 1], or a queue with a
    network that cannot mine, is refused."""
    relay = _relay()
    argv = ["--minutes", "1", "--data", str(photos), "--queue", "D", "--device", "cpu"]
    plain = _slot_runs(argv, tmp_path / "plain", "D")
    mined = _slot_runs(
        [*argv, "--colour-mined", "0.5", "--mine-score", "rgb"], tmp_path / "mined", "D"
    )
    assert [(r.data.colour_mined, r.data.mine_score) for r in mined] == [
        (0.5, "rgb"),
        (0.0, "chroma"),
    ]
    assert [r.data.colour_mined for r in plain] == [0.0, 0.0]
    # The rest of the colour part is the same stage.
    assert [r.data.colour_swap for r in mined] == [r.data.colour_swap for r in plain]
    record = json.loads((tmp_path / "mined" / "relay.json").read_text())
    assert (record["colour_mined"], record["mine_score"]) == (0.5, "rgb")
    # The table's title (and the candidates' descriptions, in the same words) say it.
    for folder, said in (("mined", "0.5 of its patches mined by rgb error"), ("plain", "")):
        args = relay.parse(
            [*argv, "--colour-mined", "0.5" if said else "0", "--mine-score", "rgb"]
            + ["--colour", "--out", str(tmp_path / folder)]
        )
        relay.write_table(tmp_path / folder / "relay.md", [], args)
        title = (tmp_path / folder / "relay.md").read_text().splitlines()[0]
        assert ("mined" in title) == bool(said) and said in title and "cool-down" in title
    for bad in (["--colour-mined", "0.5"], ["--colour-mined", "1.5", "--colour"]):
        with pytest.raises(SystemExit):
            relay.parse([*argv, "--out", str(tmp_path / "bad"), *bad])
        assert "--colour-mined" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
    # A queued network that cannot mine (universal trains on a new pattern each step) is
    # refused before the network ahead of it trains, in one line, leaving no folder.
    both = ["--minutes", "1", "--data", str(photos), "--queue", "D", "universal", "--device", "cpu"]
    assert (
        relay.main([*both, "--colour", "--colour-mined", "0.5", "--out", str(tmp_path / "bad")])
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert "universal: data.colour_mined" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def test_a_run_that_sets_up_long_shortens_the_next_not_the_slot(photos, tmp_path, monkeypatch):
    """A colour slot's runs within its wall time, on a clock the fake runs advance by their
    set-up and their training: a colour part that sets up for 90 s (mining its patches) where 15
    were expected leaves its cool-down what is left of the slot, so the slot ends within it; one
    that sets up as expected leaves the cool-down its planned third, never more; one that took
    the whole slot leaves the cool-down the shortest run the relay trains."""
    import splitcam.training as training

    relay = _relay()
    argv = ["--minutes", "31", "--data", str(photos), "--queue", "D", "--device", "cpu"]
    args = relay.parse([*argv, "--out", str(tmp_path), "--colour"])
    relay.start_folder(tmp_path, args)
    configs = relay.relay_configs("D", args, tmp_path, 30.0)
    overhead, slot_s = 30.0, 30.0 * 60 + 30.0

    class Result:
        failure, run_dir = None, None

    def slot(first_setup_s: float) -> tuple[list[float], float]:
        clock, limits = [0.0], []

        def fake_train(config, progress=False):
            limits.append(config.run.time_limit)
            clock[0] += (first_setup_s if len(limits) == 1 else 15.0) + 60 * limits[-1]
            return Result()

        monkeypatch.setattr(training, "train", fake_train)
        monkeypatch.setattr(relay, "summarise", lambda name, config, result: {"model": name})
        parts, _ = relay.run_slot("D", configs, slot_s, overhead, False, clock=lambda: clock[0])
        assert len(parts) == 2
        return limits, clock[0]

    assert [c.run.time_limit for c in configs] == pytest.approx([20.0, 10.0])
    limits, ended = slot(90.0)
    # 20 min + 90 s of the 30.5-min slot gone: 8.75 min left after the cool-down's own 15 s.
    assert limits == pytest.approx([20.0, (slot_s - 20 * 60 - 90 - 15) / 60])
    assert ended == pytest.approx(slot_s)
    limits, ended = slot(15.0)
    assert limits == pytest.approx([20.0, 10.0]) and ended == pytest.approx(slot_s)
    limits, _ = slot(12.0 * 60)
    assert limits == pytest.approx([20.0, relay.MIN_SLOT_MIN])


def test_stage_files_of_segments_recorded_before_a_setting_was_added(tmp_path) -> None:
    """A shipped model's relay segment recorded before a setting existed (here data.val_scale,
    popped from the record) is written out with the value that reproduces it, and reads back
    as the record does under TrainConfig.from_saved (it once refused: "does not read back")."""
    from splitcam.io.weights import MODELS_DIR
    from splitcam.training import TrainConfig

    meta = json.loads((MODELS_DIR / "D.json").read_text())
    relayed = [s for s in meta["provenance"]["segments"] if "/relay/" in s.get("config_file", "")]
    assert relayed, "the shipped D has a stage trained by the relay"
    for segment in meta["provenance"]["segments"]:
        segment["settings"]["data"].pop("val_scale", None)
    candidate = tmp_path / "D.json"
    candidate.write_text(json.dumps(meta))
    written = _relay().write_stage_files(candidate, tmp_path / "repo")
    assert [p.relative_to(tmp_path / "repo").as_posix() for p in written] == [
        s["config_file"] for s in relayed
    ]
    for path, segment in zip(written, relayed, strict=True):
        read = TrainConfig.from_file(path)
        assert read.data.val_scale == 1.0
        assert read.data.scales == segment["settings"]["data"]["scales"]
        assert read.optim.steps == segment["settings"]["optim"]["steps"]


def test_threads_reach_every_run_and_the_gate_keeps_its_own_default(tmp_path, monkeypatch):
    """``--threads`` sets each run's CPU threads (two relays side by side on a CPU, each at
    torch's own count, share its cores at a fraction of the speed); without it a run keeps
    torch's count, and the gate scores with the count given or else its own default."""
    relay = _relay()
    argv = ["--minutes", "1", "--data", str(tmp_path), "--queue", "D", "--device", "cpu"]
    threads = {}
    for flags in ([], ["--threads", "1"]):
        out = tmp_path / ("one" if flags else "default")
        threads[bool(flags)] = [run.run.threads for run in _slot_runs([*argv, *flags], out, "D")]
    assert threads == {False: [None, None], True: [1, 1]}

    # What the gate is handed: a relay folder with one candidate, the scoring itself stubbed.
    from splitcam.training import gate

    folder = tmp_path / "default"
    (folder / "candidates").mkdir()
    (folder / "candidates" / "D.json").write_text("{}")
    handed = []

    def scoring(found, data, threads):
        handed.append(threads)
        raise KeyboardInterrupt  # stop before any table is written

    monkeypatch.setattr(gate, "gate", scoring)
    for flags in ([], ["--threads", "3"]):
        with pytest.raises(KeyboardInterrupt):
            relay.main(["--gate", str(folder), "--data", str(tmp_path), *flags])
    assert handed == [relay.GATE_THREADS, 3] and relay.GATE_THREADS == 2


def test_cpu_share_tells_a_busy_process_from_an_idle_one() -> None:
    """What the relay's "CPU used" column measures: the process's CPU time over its wall time
    and threads, near 0 for a process that waits and well above it for one that computes."""
    import time

    relay = _relay()

    def share(work) -> float:
        cpu, wall = time.process_time(), time.monotonic()
        work()
        return relay.cpu_share(time.process_time() - cpu, time.monotonic() - wall, 1)

    def spin() -> None:
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            pass

    idle, busy = share(lambda: time.sleep(0.3)), share(spin)
    assert idle < 0.1 and busy > 3 * idle and busy > 0.2
    assert relay.cpu_share(3.0, 2.0, 3) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="threads"):
        relay.cpu_share(1.0, 1.0, 0)
