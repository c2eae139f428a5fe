"""The worked result of `physics.optics` (docs/results/optics/): 2x2 Bayer-type routers designed
from a random and from a lens-array start, for the reconstruction (closed-form LMMSE) and for
routing (RGGB collection efficiency), in two geometries; their collection efficiency, kernels and
height maps, and their image quality against pattern A and the Bayer filter at equal noise and
at equal exposure.

    SPLITCAM_DATA=DIR python studies/optics/worked_result.py --out docs/results/optics

Every router is scored by the closed-form LMMSE of its kernels (model.md §10), and so are A
and the Bayer filter, so the comparison is between sensors, not between reconstructions. Images:
the first ``--images`` of Kodak24 and of McMaster (reporting only; nothing here is tuned on them),
found by name under the data root ``DIR`` (``splitcam data download kodak24 mcmaster --to DIR``;
docs/commands.md).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from splitcam import patterns
from splitcam.data.testsets import load_images
from splitcam.design import design_metasurface
from splitcam.evaluation import evaluate
from splitcam.evaluation.exposure import default_exposures, exposure_study, write_study
from splitcam.evaluation.tables import markdown_tables, summarise
from splitcam.physics.optics import Optics, bayer_collection, pattern_of, profile
from splitcam.recon.closed_form import closed_form_lmmse
from splitcam.viz.patterns import draw_height_maps, draw_pattern

#: The two geometries: the package defaults (1 µm pixels, 2 µm above the photodiodes), and 2 µm
#: pixels 4 µm below the metasurface, where red light can be steered across a pixel.
GEOMETRIES = {
    "p1": Optics(),
    "p2": Optics(pitch=2.0, distance=4.0, samples=10),
}
STARTS = ("random", "lens")
OBJECTIVES = ("lmmse", "routing")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="docs/results/optics")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--lr", type=float, default=0.1)
    parser.add_argument("--images", type=int, default=4, help="per test set")
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    out = Path(args.out)
    (out / "routers").mkdir(parents=True, exist_ok=True)
    began = time.perf_counter()

    rows, files, heights = [], [], []
    for geo, optics in GEOMETRIES.items():
        for start in STARTS:
            flat_start = pattern_of(profile(start, (2, 2), optics, 0), (2, 2), optics)
            for objective in OBJECTIVES:
                name = f"{geo}-{start}-{objective}"
                result = design_metasurface(
                    (2, 2),
                    optics,
                    init=start,
                    objective=objective,
                    steps=args.steps,
                    lr=args.lr,
                    seed=0,
                    name=name,
                )
                path = out / "routers" / f"{name}.toml"
                patterns.save(result.pattern, path)
                np.save(path.with_suffix(".npy"), result.height.numpy())
                draw_pattern(result.pattern, path.with_suffix(".png"))
                files.append(path)
                heights.append((name, result.height.numpy(), optics))
                kernels = result.pattern.kernels
                rows.append(
                    {
                        "router": name,
                        "pitch_um": optics.pitch,
                        "distance_um": optics.distance,
                        "start": start,
                        "objective": objective,
                        "collection_start": bayer_collection(flat_start),
                        "collection": bayer_collection(result.pattern),
                        "light_kept": float(kernels.sum((2, 3)).mean()),
                        "lmmse_psnr_before": result.psnr_before,
                        "lmmse_psnr_after": result.psnr_after,
                        "seconds": result.seconds,
                    }
                )
                print(
                    f"{name}: RGGB collection "
                    + "/".join(f"{v:.1%}" for v in rows[-1]["collection"])
                    + f", closed-form LMMSE at sigma 0 {result.psnr_after[0.0]:.2f} dB "
                    f"({result.seconds:.1f} s)",
                    flush=True,
                )
    draw_height_maps(
        [(n, h) for n, h, _ in heights],
        out / "height_maps.png",
        pitch=[o.pitch for *_, o in heights],
        max_height=[o.max_height for *_, o in heights],
    )

    images = [(dataset, load_images(dataset)[: args.images]) for dataset in ("kodak24", "mcmaster")]
    methods = []
    for spec in ("A", "bayer", *files):
        method = closed_form_lmmse(patterns.get(spec))
        method.name = f"lmmse-{patterns.get(spec).name}"
        methods.append(method)
    evaluated = evaluate(
        methods, images, [0.0, 5.0, 10.0, 15.0, 20.0], out / "equal_noise", progress=True
    )
    flat = [img for _, imgs in images for img in imgs]
    study = exposure_study(
        flat,
        patterns=[patterns.get(p) for p in ["A", "bayer", *map(str, files)]],
        photons=default_exposures(7),
    )
    write_study(
        study,
        None,
        out / "equal_exposure",
        note=f"Images: the first {args.images} of Kodak24 and of McMaster. Read noise 2 e-, no "
        "saturation or ADC. Command: `SPLITCAM_DATA=DIR python "
        "studies/optics/worked_result.py` (DIR: the data root holding kodak24/ and mcmaster/)",
    )
    info = {
        "command": " ".join(["python", *sys.argv]),
        "machine": f"{platform.machine()}, {torch.get_num_threads()} threads, torch "
        f"{torch.__version__}",
        "seconds": time.perf_counter() - began,
        "steps": args.steps,
        "lr": args.lr,
        "routers": rows,
    }
    (out / "routers.json").write_text(json.dumps(info, indent=1) + "\n")
    _write_readme(out, rows, summarise(evaluated), study, info)
    print(f"wrote {out}/README.md ({info['seconds']:.0f} s)")
    return 0


def _pct(values: list[float]) -> str:
    return " / ".join(f"{100 * v:.1f}" for v in values)


def _write_readme(out: Path, rows: list[dict], summary: dict, study: dict, info: dict) -> None:
    lines = [
        "# A metasurface router designed with the reconstruction (issue 12's worked result)",
        "",
        f"Command: `{info['command']}` with `SPLITCAM_DATA` the data root of Kodak24 and McMaster "
        f"({info['machine']}; {info['seconds'] / 60:.1f} min in all, {info['steps']} Adam steps "
        f"at lr {info['lr']} per design).",
        "",
        "Scalar thin-element model (`splitcam.physics.optics`): a height map of a dielectric of "
        "index 2.0 in air (at most 1.2 µm), normal incidence, angular-spectrum propagation to the"
        " photodiodes, Gaussian colour bands at 610/540/460 nm (σ 30 nm), 16 wavelengths from 400"
        " to 700 nm, 3x3-pixel kernels. Geometry p1: 1 µm pixels 2 µm below the metasurface (the "
        "defaults); p2: 2 µm pixels 4 µm below it. Each router is one 2x2 period designed by Adam"
        " on its height map (sigmoid-bounded) from a random or a lens-array start, for the "
        "closed-form LMMSE error averaged over σ = 0-20 (`lmmse`), or for the geometric mean of "
        "the R/G/B collection efficiencies into an RGGB arrangement (`routing`).",
        "",
        "## Collection efficiency into RGGB pixels",
        "",
        "Band-averaged share of each colour's light over the period reaching the pixels of that "
        "colour (R at (0, 0)); a Bayer filter: 25 / 50 / 25 %, a perfect router 100 / 100 / 100 "
        "%. Zou et al. (Nat. Commun. 2022) measured peak (best-wavelength, not band-averaged) "
        "collection of 58 / 59 / 49 % for their pixel-level router, designed full-wave; a "
        "scalar thin-element model ignores the meta-atoms' coupling and the near field, so only "
        "the order of magnitude compares.",
        "",
        "| router | pitch / distance (µm) | start | objective | R / G / B % (start) | "
        "R / G / B % (designed) | light kept % | LMMSE σ=0 / σ=15 (dB, closed form) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['router']} | {r['pitch_um']:g} / {r['distance_um']:g} | {r['start']} | "
            f"{r['objective']} | {_pct(r['collection_start'])} | {_pct(r['collection'])} | "
            f"{100 * r['light_kept']:.1f} | {r['lmmse_psnr_after'][0.0]:.2f} / "
            f"{r['lmmse_psnr_after'][15.0]:.2f} |"
        )
    lines += [
        "",
        "`light kept`: the mean share of a pixel's light that lands inside its 3x3 kernel "
        "window (the rest is evanescent or lands farther away: lost, never created).",
        "",
        "Height maps: ![height maps](height_maps.png). Kernels of each router, drawn like the "
        "pattern figures: `routers/<router>.png`; the height maps themselves (µm): "
        "`routers/<router>.npy`; the pattern files: `routers/<router>.toml`.",
        "",
        "## Image quality at equal noise (the paper's protocol)",
        "",
        "Closed-form LMMSE of every sensor, Gaussian noise σ on the raw image (8-bit units).",
        "",
        markdown_tables(summary),
        "## Image quality at equal exposure (photon model)",
        "",
        "Shot noise and 2 e- read noise at the same photon flux for every sensor; `N`: the "
        "photo-electrons a lossless, filterless pixel collects from a white scene. Full tables, "
        "crossovers and chart: [equal_exposure/exposure.md](equal_exposure/exposure.md).",
        "",
        "![exposure](equal_exposure/exposure.png)",
        "",
    ]
    photons = sorted(next(iter(study.values())))
    lines.append("| sensor | " + " | ".join(f"N={n:.3g}" for n in photons) + " |")
    lines.append("|---|" + "---|" * len(photons))
    for label, per in study.items():
        lines.append(f"| {label} | " + " | ".join(f"{per[n]['psnr']:.2f}" for n in photons) + " |")
    (out / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())
