"""Training curves (splitcam.viz.curves): what they draw for the runs users give them."""

from __future__ import annotations

import json

import pytest

from splitcam.cli import main


def _run(folder, keys):
    folder.mkdir()
    rows = [{"step": s, "time": 10.0 * s, "loss": 0.01, "train_psnr": 30.0} for s in (1, 2, 3)]
    rows += [{"step": 3, "time": 31.0, "val_psnr": 31.0, **{k: 31.0 for k in keys}}]
    (folder / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return folder


@pytest.mark.parametrize("keys", [["val_psnr_N30", "val_psnr_N300"], ["val_psnr_0", "val_psnr_15"]])
def test_plot_draws_runs_of_either_noise_model(tmp_path, keys):
    """`splitcam plot` of one run and of two runs, under the photon model (labels N30) and the
    Gaussian one: every validation level gets its curve, named by its level."""

    a, b = _run(tmp_path / "a", keys), _run(tmp_path / "b", keys)
    assert main(["plot", str(a)]) == 0 and (a / "curves.png").is_file()
    out = tmp_path / "both.png"
    assert main(["plot", str(a), str(b), "--out", str(out)]) == 0 and out.is_file()

    import matplotlib.figure

    from splitcam.viz.curves import compare_runs

    drawn = []
    original = matplotlib.figure.Figure.savefig

    def keep(fig, *args, **kwargs):
        drawn.append(fig)
        return original(fig, *args, **kwargs)

    matplotlib.figure.Figure.savefig = keep
    try:
        compare_runs([a, b], tmp_path / "again.png")
    finally:
        matplotlib.figure.Figure.savefig = original
    labels = [line.get_label() for line in drawn[0].axes[0].get_lines()]
    expected = ["N=30 e⁻", "N=300 e⁻"] if "N" in keys[0] else ["σ=0", "σ=15"]
    assert labels == [f"{run}, {level}" for run in ("a", "b") for level in expected]


def test_training_minutes_leave_out_the_pause_of_a_resumed_run():
    """A run logged every 10 s, stopped for 80 minutes and resumed: the curves' time axis counts
    the pause as one ordinary gap, and an uninterrupted run keeps its wall-clock minutes."""
    from splitcam.viz.curves import active_minutes

    times = [0, 10, 20, 30, 4830, 4840, 4850]
    minutes = active_minutes([{"step": 10 * i, "time": t} for i, t in enumerate(times)])
    assert minutes == pytest.approx([t / 60 for t in (0, 10, 20, 30, 40, 50, 60)])
    steady = [0, 9, 21, 30, 41]
    got = active_minutes([{"step": i, "time": t} for i, t in enumerate(steady)])
    assert got == pytest.approx([t / 60 for t in steady])
