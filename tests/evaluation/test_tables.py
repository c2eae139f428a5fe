"""Result tables (splitcam.evaluation.tables): rows written without later columns still read."""

from __future__ import annotations

from splitcam.evaluation import markdown_tables
from splitcam.evaluation.tables import read_rows


def test_results_without_a_domain_column_read_as_srgb(tmp_path) -> None:
    path = tmp_path / "per_image.csv"
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000,photons\n"
        "m,D,set,a,0,30.5,0.9,2.0,100\n"
        "m,D,set,b,0,31.5,0.9,2.0\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.domain, row.level, row.psnr) == ("srgb", "N100", 30.5)
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000,photons,domain\n"
        "m,D,set,a,5,30.5,0.9,2.0,0,linear\n"
        "m,D,set,b,5,31.5,0.9,2.0,0,lin\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.domain, row.label) == ("linear", "m (linear)")
    assert markdown_tables({"m": {"pattern": "D", "s": {}}}).startswith("Light domain: srgb")


def test_results_written_before_the_photons_column_still_read(tmp_path) -> None:
    from splitcam.evaluation.tables import read_rows

    path = tmp_path / "per_image.csv"
    path.write_text(
        "method,pattern,dataset,image,sigma,psnr,ssim,ciede2000\n"
        "m,D,set,a,5,30.5,0.9,2.0\n"
        "m,D,set,b,5,31.5,0.9\n"  # cut short by a kill
    )
    (row,) = read_rows(path)
    assert (row.sigma, row.photons, row.level, row.psnr) == (5.0, 0.0, "5", 30.5)


def test_kodak_minus_mcmaster_drop_per_method_and_level() -> None:
    """The drop table is each method's Kodak24 mean minus its McMaster mean, cell by cell;
    absent when one of the two sets is missing."""

    def stats(psnr: float) -> dict:
        return {"psnr": psnr, "ssim": 0.9, "ciede2000": 1.0, "n_images": 2, "n_infinite": 0}

    summary = {
        "net-bayer": {
            "pattern": "bayer",
            "domain": "srgb",
            "kodak24": {"0": stats(41.47), "15": stats(31.0)},
            "mcmaster": {"0": stats(35.40), "15": stats(30.25)},
        },
        "bayer+demosaicnet": {
            "pattern": "bayer",
            "domain": "srgb",
            "kodak24": {"0": stats(42.09)},
            "mcmaster": {"0": stats(39.15)},
        },
    }
    text = markdown_tables(summary)
    section = text.split("### kodak24 minus mcmaster")[1].splitlines()
    assert "| net-bayer | 6.07 | 0.75 |" in section
    assert "| bayer+demosaicnet | 2.94 | – |" in section
    del summary["net-bayer"]["mcmaster"], summary["bayer+demosaicnet"]["mcmaster"]
    assert "minus" not in markdown_tables(summary)


def test_a_folder_named_all_never_merges_with_the_pool() -> None:
    """A folder of images called ``all`` keeps its own rows; the pool of every set is then
    ``all-sets`` (the two used to merge silently into one table of the wrong images)."""
    from splitcam.evaluation.tables import EvalRow, summarise

    def row(dataset: str, image: str, psnr: float) -> EvalRow:
        return EvalRow("m", "D", dataset, image, 0.0, psnr, 0.9, 1.0)

    rows = [row("all", "a", 30.0), row("all", "b", 32.0), row("colourful", "c", 40.0)]
    summary = summarise(rows)["m"]
    assert summary["all"]["0"]["psnr"] == 31.0 and summary["all"]["0"]["n_images"] == 2
    assert summary["all-sets"]["0"]["n_images"] == 3
