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


def test_exposure_chart_gives_a_pattern_one_colour_and_each_kind_of_network_a_line_style(
    tmp_path, monkeypatch
):
    from matplotlib.axes import Axes

    from splitcam.viz.charts import exposure_chart

    drawn = {}
    plot = Axes.plot

    def spy(self, *args, **kwargs):
        drawn[kwargs.get("label")] = (str(kwargs.get("color")), str(kwargs.get("ls")))
        return plot(self, *args, **kwargs)

    monkeypatch.setattr(Axes, "plot", spy)
    per = {10.0: {"psnr": 20.0, "ciede2000": 9.0}, 100.0: {"psnr": 25.0, "ciede2000": 6.0}}
    labels = ["A", "bayer", "net-u-A", "net-u-bayer", "net-A-photon", "net-bayer-photon"]
    networks = {"net-u-A": "A", "net-u-bayer": "bayer", "net-A-photon": "A"}
    networks["net-bayer-photon"] = "bayer"
    exposure_chart({k: per for k in labels}, tmp_path / "e.png", networks=networks)
    assert (tmp_path / "e.png").stat().st_size > 0
    assert drawn["A"][0] == drawn["net-u-A"][0] == drawn["net-A-photon"][0]
    assert drawn["bayer"][0] == drawn["net-u-bayer"][0] == "black"
    assert drawn["net-u-A"][1] == drawn["net-u-bayer"][1] != drawn["net-A-photon"][1]
    assert drawn["A"][1] == "--" and drawn["net-A-photon"][1] == drawn["net-bayer-photon"][1]


def test_the_papers_curves_are_drawn_where_the_title_says_so(tmp_path, monkeypatch):
    """The title promises the paper's network grey dashed: each reference is drawn, at its own
    points and labelled; without references neither the lines nor the promise."""
    from matplotlib.axes import Axes

    from splitcam.viz.charts import sigma_chart

    drawn, titles = {}, []
    plot, set_title = Axes.plot, Axes.set_title

    def spy(self, *args, **kwargs):
        if str(kwargs.get("gid", "")).startswith("reference:"):
            drawn[kwargs["gid"]] = (list(args[0]), list(args[1]), kwargs.get("color"))
        return plot(self, *args, **kwargs)

    def title_spy(self, label, *args, **kwargs):
        titles.append(label)
        return set_title(self, label, *args, **kwargs)

    monkeypatch.setattr(Axes, "plot", spy)
    monkeypatch.setattr(Axes, "set_title", title_spy)
    per = {"0": {"psnr": 30.0, "ciede2000": 2.0}, "10": {"psnr": 28.0, "ciede2000": 3.0}}
    paper = {"D": [(10.0, 36.62), (0.0, 40.35)], "bayer": [(0.0, 39.0), (10.0, 33.0)]}
    sigma_chart([("net-D", per)], tmp_path / "c.png", paper)
    assert drawn["reference:D"] == ([0.0, 10.0], [40.35, 36.62], "grey")
    assert drawn["reference:bayer"][:2] == ([0.0, 10.0], [39.0, 33.0])
    assert "grey dashed" in titles[0]
    drawn.clear(), titles.clear()
    sigma_chart([("net-D", per)], tmp_path / "d.png")
    assert drawn == {} and "grey dashed" not in titles[0]
