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
