"""Design search (splitcam.design.search, viz.search, design/optics --search) on tiny budgets."""

from __future__ import annotations

import sys

import pytest

optuna = pytest.importorskip("optuna")

from splitcam import patterns  # noqa: E402
from splitcam.cli import main  # noqa: E402
from splitcam.design.search import open_search, search_metasurfaces, search_patterns  # noqa: E402
from splitcam.physics.optics import Optics  # noqa: E402
from splitcam.viz.search import draw_front  # noqa: E402

#: Small optics (3 wavelengths, 4 samples per pixel): a design step in milliseconds.
SMALL = Optics(pitch=0.5, samples=4, distance=1.0, wavelengths=[450.0, 550.0, 650.0], guard=1)
COMPLETE, PRUNED = optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED


def _collection(fig, label: str):
    (ax,) = fig.axes
    found = [c for c in ax.collections if c.get_label() == label]
    assert len(found) == 1, [c.get_label() for c in ax.collections]
    return found[0]


def test_a_tiny_search_finishes_resumes_and_its_best_trial_reproduces(tmp_path) -> None:
    space = {"steps": 20, "init": ("choice", "support", "random")}
    search = search_patterns(
        patterns.get("D"), trials=3, folder=tmp_path, space=space, report_every=10
    )
    trials = search.study.trials
    assert [t.state for t in trials] == [COMPLETE] * 3  # the warm-up (100 steps) spares them
    # the designer's defaults come first (steps held at 20), then the sampler's draws
    assert trials[0].params == {"lr": 0.1, "steps": 20, "init": "support", "objective": "mse"}
    assert trials[0].user_attrs["baseline"] is True
    assert all(sorted(t.intermediate_values) == [10, 20] for t in trials)
    assert all(t.values[0] == t.intermediate_values[20] for t in trials)
    assert all(search.pattern_file(t.number).is_file() for t in trials)

    # resumes from its journal: a second call adds trials to the same study
    again = search_patterns(
        patterns.get("D"), trials=1, folder=tmp_path, space=space, report_every=10
    )
    assert len(again.study.trials) == 4
    assert "baseline" not in again.study.trials[3].user_attrs
    assert len(open_search(tmp_path).finished()) == 4
    with pytest.raises(ValueError, match="other settings .*sigmas"):
        search_patterns(patterns.get("D"), trials=1, folder=tmp_path, sigmas=[5.0], space=space)

    # the best trial reproduces: designed again from its parameters, the same score and pattern
    best = again.trial()
    assert best.values[0] == max(t.values[0] for t in again.finished())
    result, (score,) = open_search(tmp_path).reproduce()
    assert score == best.values[0]
    assert patterns.load(again.pattern_file(best.number)).equals(result.pattern, atol=1e-12)
    assert len(result.history) == 20


def test_one_stage_is_design_pattern_with_the_trials_settings(tmp_path) -> None:
    from splitcam.design import design_pattern

    space = {"steps": 12, "init": "random", "seed": 3, "objective": "psnr"}
    search = search_patterns(
        patterns.get("A"), trials=1, folder=tmp_path, space=space, report_every=0
    )
    (trial,) = search.finished()
    assert trial.intermediate_values == {12: trial.values[0]}
    plain = design_pattern(patterns.get("A"), **{k: v for k, v in trial.params.items()})
    designed = patterns.load(search.pattern_file(trial.number))
    assert designed.equals(plain.pattern, atol=1e-12)

    # a design that ran all its steps is kept, however far below the median
    bad = {"lr": 1e-4, "init": "random", "seed": 0}
    kept = search_patterns(
        patterns.get("D"),
        trials=2,
        folder=tmp_path / "kept",
        space={"steps": 10, "lr": ("log", 1e-4, 0.5)},
        report_every=0,
        startup=1,
        warmup=0,
        baseline=False,
        enqueue=[{"lr": 0.1, "init": "support"}, bad],
    )
    good, low = kept.study.trials
    assert (good.state, low.state) == (COMPLETE, COMPLETE)
    assert low.values[0] < good.values[0] - 1.0


def test_pruning_stops_a_trial_below_the_median(tmp_path) -> None:
    good = {"lr": 0.1, "init": "support"}
    bad = {"lr": 1e-4, "init": "random", "seed": 0}  # barely moves from a random start
    search = search_patterns(
        patterns.get("D"),
        trials=3,
        folder=tmp_path,
        space={"steps": 20, "lr": ("log", 1e-4, 0.5), "objective": "mse"},
        report_every=5,
        startup=2,
        warmup=0,
        baseline=False,
        enqueue=[good, {**good, "lr": 0.2}, bad],
    )
    first, second, third = search.study.trials
    assert (first.state, second.state) == (COMPLETE, COMPLETE)
    assert third.state == PRUNED and third.last_step == 5  # stopped at its first report
    assert third.params["lr"] == 1e-4
    median = (first.intermediate_values[5] + second.intermediate_values[5]) / 2
    assert third.intermediate_values[5] < median - 1.0  # clearly below, in dB
    assert not search.pattern_file(third.number).exists()
    assert {t.number for t in search.best()} == {0, 1}


def test_a_two_score_metasurface_search_draws_its_pareto_front(tmp_path) -> None:
    search = search_metasurfaces(
        (2, 2), SMALL, trials=5, folder=tmp_path, steps=3, startup=2, seed=1
    )
    finished = search.finished()
    assert len(finished) == 5
    # the geometry of the optics with the designer's defaults, for each objective, comes first
    assert [t.params["objective"] for t in finished[:2]] == ["lmmse", "routing"]
    assert all(t.params["distance"] == SMALL.distance for t in finished[:2])
    front = search.best()
    assert front and all(len(t.values) == 2 for t in front)

    def dominates(a, b) -> bool:
        return all(x >= y for x, y in zip(a, b, strict=True)) and a != b

    on_front = {t.number for t in front}
    for t in finished:
        beaten = any(dominates(o.values, t.values) for o in finished)
        assert beaten == (t.number not in on_front)
    assert [t.values[0] for t in front] == sorted((t.values[0] for t in front), reverse=True)

    fig = draw_front(
        [(t.values[1], t.values[0]) for t in finished],
        [(t.values[1], t.values[0]) for t in front],
        labels=[str(t.number) for t in front],
        baselines=[(t.values[1], t.values[0]) for t in finished[:2]],
    )
    assert len(_collection(fig, "Pareto front").get_offsets()) == len(front)
    assert len(_collection(fig, "trials").get_offsets()) == 5
    assert len(_collection(fig, "baselines").get_offsets()) == 2
    assert sorted(t.get_text() for t in fig.axes[0].texts) == sorted(str(n) for n in on_front)

    values = search.reproduce(front[-1].number)[1]
    assert list(values) == front[-1].values
    height = search.pattern_file(front[-1].number).with_suffix(".npy")
    assert height.is_file()


def test_cli_design_search(tmp_path, capsys) -> None:
    out, study = tmp_path / "best.toml", tmp_path / "study"
    argv = ["design", "--search", "2", "--steps", "10", "--study", str(study)]
    assert main([*argv, "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "2 trials, 2 finished, 0 pruned (fixed: steps 10)" in printed
    assert "| trial | PSNR (dB) | vs default |" in printed
    assert "designed again" in printed and "not reproduced" not in printed
    best = patterns.load(out)
    assert best.name == "D-designed" and best.metadata["steps"] == 10
    assert out.with_suffix(".png").is_file() and (study / "curves.png").is_file()
    assert main([*argv, "--out", str(out), "--quiet", "--search-seed", "1"]) == 0  # resumes
    assert "4 trials, 4 finished" in capsys.readouterr().out
    assert main([*argv, "--objective", "network", "--out", str(out)]) == 1
    assert "closed-form objectives" in capsys.readouterr().err


def test_cli_optics_search(tmp_path, capsys) -> None:
    out, study = tmp_path / "router.toml", tmp_path / "study"
    argv = ["optics", "--pitch", "0.5", "--samples", "4", "--distance", "1", "--design"]
    argv += ["--search", "3", "--steps", "2", "--study", str(study), "--out", str(out)]
    assert main([*argv, "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "3 trials, 3 finished (fixed: distance 1)" in printed
    assert "Pareto front" in printed and "not reproduced" not in printed
    assert patterns.load(out).period == (2, 2)
    for path in (out.with_suffix(".npy"), out.with_suffix(".png"), study / "front.png"):
        assert path.is_file()
    assert main([*argv, "--profile", "flat"]) == 1
    assert "random or lens" in capsys.readouterr().err


def test_a_missing_optuna_says_how_to_install_it(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.setitem(sys.modules, "optuna", None)  # import optuna fails
    argv = ["design", "--search", "1", "--study", str(tmp_path), "--out", str(tmp_path / "x.toml")]
    assert main(argv) == 1
    assert "needs optuna: pip install 'splitcam[search]'" in capsys.readouterr().err
    with pytest.raises(ModuleNotFoundError, match=r"splitcam\[search\]"):
        search_patterns(patterns.get("D"), trials=1, folder=tmp_path)


def test_bad_search_settings_are_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="unknown setting"):
        search_patterns(patterns.get("D"), trials=1, folder=tmp_path, space={"temperature": 1.0})
    with pytest.raises(ValueError, match="closed-form objectives"):
        search_patterns(
            patterns.get("D"), trials=1, folder=tmp_path, space={"objective": "network"}
        )
    with pytest.raises(ValueError, match="low, high"):
        search_patterns(
            patterns.get("D"), trials=1, folder=tmp_path, space={"lr": ("log", 0.5, 0.1)}
        )
    with pytest.raises(ValueError, match="2x2"):
        search_metasurfaces(
            (1, 3), SMALL, trials=1, folder=tmp_path, space={"objective": "routing"}
        )
    with pytest.raises(ValueError, match="above the spacer"):
        search_metasurfaces((2, 2), SMALL, trials=1, folder=tmp_path, space={"index": 1.0})
