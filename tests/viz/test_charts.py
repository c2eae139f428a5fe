"""Sigma charts (splitcam.viz.charts): every line told apart."""

from __future__ import annotations


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
