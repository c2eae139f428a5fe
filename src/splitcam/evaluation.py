"""The paper's evaluation protocol (SPEC section 7) for any set of reconstruction methods.

Every method sees the same scenes and the same noise: the raw image of each scene is simulated
with the method's pattern, and the noise is drawn from a generator seeded by the image name and
sigma (:func:`splitcam.noise.evaluation_noise`). Outputs are clamped, rounded to 8 bits and scored
with PSNR, SSIM and CIEDE2000 (:mod:`splitcam.metrics`).
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from .metrics import compute_all, mean_over_images
from .noise import add_evaluation_noise
from .patterns import Pattern
from .sensor import SplitterSensor

METRICS = ("psnr", "ssim", "ciede2000")
Images = Sequence[tuple[str, torch.Tensor]]


class Method(Protocol):
    """A reconstruction method: a pattern plus ``reconstruct(raw, sigma) -> rgb``."""

    name: str
    pattern: Pattern

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor: ...


class NetworkMethod:
    """A trained run (fixed or learned pattern + network) as an evaluation method.

    Args:
        system: From :func:`splitcam.training.load_system`.
        name: Label in tables (default: the run folder's name).
        tile: Tile size for :func:`splitcam.inference.reconstruct`.
        fast: bfloat16 autocast and channels-last inference (see ``reconstruct``).
    """

    def __init__(self, system, name: str, tile: int | None = 512, fast: bool = False) -> None:
        self.system = system
        self.name = name
        self.pattern = system.sensor.to_pattern()
        self.tile = tile
        self.fast = fast

    def reconstruct(self, raw: torch.Tensor, sigma: float) -> torch.Tensor:
        from .inference import reconstruct

        return reconstruct(self.system.network, raw, tile=self.tile, bf16=self.fast,
                           channels_last=self.fast)

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike, name: str | None = None,
                        tile: int | None = 512, fast: bool = False) -> NetworkMethod:
        from .training import load_system
        from .training.checkpoint import resolve

        path = Path(path)
        label = name or (path.name if path.is_dir() else resolve(path).parent.name)
        return cls(load_system(path), label, tile, fast)


@dataclass
class EvalRow:
    method: str
    pattern: str
    dataset: str
    image: str
    sigma: float
    psnr: float
    ssim: float
    ciede2000: float


def simulate_and_reconstruct(method: Method, sensor: SplitterSensor, image_name: str,
                             rgb: torch.Tensor, sigma: float) -> torch.Tensor:
    """One step of the protocol: the raw image of ``rgb`` through ``sensor`` (float64), the
    evaluation noise of ``image_name`` and ``sigma``, and the method's reconstruction, clamped.

    Shape:
        - rgb: ``(3, H, W)``; output ``(3, H, W)`` float32 in [0, 1].
    """
    with torch.no_grad():
        raw = sensor(rgb[None].double()).float()
        noisy = add_evaluation_noise(raw, image_name, sigma)
        return method.reconstruct(noisy, sigma)[0].float().clamp(0, 1)


def detail_region(rgb: torch.Tensor, size: int = 96) -> tuple[int, int, int, int]:
    """The ``size``-square window of the ground truth with the most detail (gradient energy):
    where reconstruction differences show. Chosen from the scene alone, so it is the same for
    every method. Returns ``(top, left, height, width)``."""
    grey = rgb.mean(0).numpy().astype(np.float64)
    h, w = grey.shape
    size = min(size, h, w)
    energy = np.zeros_like(grey)
    energy[:, 1:] += np.diff(grey, axis=1) ** 2
    energy[1:, :] += np.diff(grey, axis=0) ** 2
    integral = np.pad(energy.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    sums = (integral[size:, size:] - integral[:-size, size:] - integral[size:, :-size]
            + integral[:-size, :-size])
    top, left = np.unravel_index(int(np.argmax(sums)), sums.shape)
    return int(top), int(left), size, size


def evaluate(
    methods: Sequence[Method],
    datasets: Sequence[tuple[str, Images]],
    sigmas: Sequence[float],
    out: str | os.PathLike | None = None,
    *,
    save_images: bool = False,
    zoom_images: Sequence[str] | None = None,
    crop: int = 0,
    progress: bool = True,
) -> list[EvalRow]:
    """Score every method on every image at every sigma, and write the results to ``out``.

    Writes ``per_image.csv``, ``summary.json`` and ``table.md`` (see :func:`write_results`);
    with ``save_images``, the reconstructions under ``images/`` and, for each image in
    ``zoom_images`` (default: the first image of each dataset), a side-by-side zoom of all
    methods (the paper's Figs. 4, 5, 7, 8) on a chosen region: an entry ``"kodim05:200,300,96"``
    zooms on the 96-pixel square at row 200, column 300; a bare name on the image's most
    detailed region (:func:`detail_region`). ``crop`` removes that many
    border pixels before scoring (0, the paper's convention, by default).
    """
    if not methods:
        raise ValueError("expected at least one method to evaluate")
    names = [m.name for m in methods]
    if len(set(names)) != len(names):
        raise ValueError(f"expected distinct method names, got {names}")
    out_dir = Path(out) if out is not None else None
    sensors: dict[int, SplitterSensor] = {}
    rows: list[EvalRow] = []
    total = sum(len(images) for _, images in datasets) * len(sigmas) * len(methods)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, unit="recon", desc="evaluate", dynamic_ncols=True)
    zoom = (dict(parse_zoom(z) for z in zoom_images) if zoom_images is not None else
            {images[0][0]: None for _, images in datasets if images})
    for dataset, images in datasets:
        for image_name, rgb in images:
            for sigma in sigmas:
                outputs = {}
                for method in methods:
                    sensor = sensors.setdefault(id(method), SplitterSensor(method.pattern))
                    pred = simulate_and_reconstruct(method, sensor, image_name, rgb, sigma)
                    scores = compute_all(pred, rgb, crop=crop)
                    rows.append(EvalRow(method.name, method.pattern.name, dataset, image_name,
                                        float(sigma), **scores))
                    outputs[method.name] = (pred, scores)
                    if bar is not None:
                        bar.update(1)
                        bar.set_postfix_str(f"{dataset}/{image_name} s{sigma:g} "
                                            f"{method.name} {scores['psnr']:.2f} dB", refresh=False)
                if save_images and out_dir is not None:
                    _save_images(out_dir, dataset, image_name, sigma, rgb, outputs,
                                 image_name in zoom, zoom.get(image_name))
    if bar is not None:
        bar.close()
    if out_dir is not None:
        write_results(rows, out_dir)
        # The patterns go with the results, so a report can draw (learned) patterns later.
        from .patterns import save

        (out_dir / "patterns").mkdir(parents=True, exist_ok=True)
        for method in methods:
            save(method.pattern, out_dir / "patterns" / f"{method.name}.json")
    return rows


def _save_images(out_dir: Path, dataset: str, image: str, sigma: float, rgb: torch.Tensor,
                 outputs: dict, zoom: bool, region: tuple[int, int, int] | None) -> None:
    from .imageio import write_image

    safe = image.replace("/", "_")
    for name, (pred, _) in outputs.items():
        path = out_dir / "images" / name / dataset / f"{safe}_sigma{sigma:g}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_image(path, pred)
    if zoom:
        zoom_figure(rgb, outputs, out_dir / "zoom" / f"{dataset}_{safe}_sigma{sigma:g}.png",
                    region=region,
                    title=f"{dataset}/{image}, sigma {sigma:g}")


def parse_zoom(spec: str) -> tuple[str, tuple[int, int, int] | None]:
    """``"name"`` or ``"name:top,left,size"`` → ``(name, region or None)``."""
    name, _, region = spec.partition(":")
    if not region:
        return name, None
    try:
        top, left, size = (int(v) for v in region.split(","))
    except ValueError:
        raise ValueError(f"expected a zoom as IMAGE or IMAGE:TOP,LEFT,SIZE, got {spec!r}") from None
    if top < 0 or left < 0 or size < 1:
        raise ValueError(f"expected a zoom region with TOP, LEFT >= 0 and SIZE >= 1, got {spec!r}")
    return name, (top, left, size)


def zoom_figure(rgb: torch.Tensor, outputs: dict, path: Path, title: str = "",
                region: tuple[int, int, int] | None = None) -> Path:
    """Ground truth and each method's output, zoomed on ``region`` (top, left, size), by
    default the most detailed region of the scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    if region is None:
        top, left, h, w = detail_region(rgb)
    else:
        top, left, size = region
        h, w = min(size, rgb.shape[1] - top), min(size, rgb.shape[2] - left)
        if h < 1 or w < 1:
            raise ValueError(f"zoom region {region} lies outside the {tuple(rgb.shape[1:])} image")
    panels = [("ground truth", rgb, None), *((n, p, s) for n, (p, s) in outputs.items())]
    fig, axes = plt.subplots(1, len(panels) + 1, figsize=(2.6 * (len(panels) + 1), 3.1))
    axes[0].imshow(rgb.permute(1, 2, 0).numpy())
    axes[0].add_patch(Rectangle((left, top), w, h, fill=False, ec="yellow", lw=1.5))
    axes[0].set_title("scene (region in yellow)", fontsize=8)
    for ax, (name, img, scores) in zip(axes[1:], panels, strict=True):
        crop = img[:, top:top + h, left:left + w].permute(1, 2, 0).numpy()
        ax.imshow(crop, interpolation="nearest")
        label = name if scores is None else (
            f"{name}\n{scores['psnr']:.2f} dB, SSIM {scores['ssim']:.3f}, "
            f"ΔE {scores['ciede2000']:.2f}")
        ax.set_title(label, fontsize=7)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


def summarise(rows: Sequence[EvalRow]) -> dict:
    """``{method: {dataset|"all": {sigma: {metric: mean, "n_images": n, "n_infinite": k}}}}``."""
    summary: dict = {}
    methods = list(dict.fromkeys(r.method for r in rows))
    for method in methods:
        mine = [r for r in rows if r.method == method]
        groups = list(dict.fromkeys(r.dataset for r in mine))
        entry: dict = {"pattern": mine[0].pattern}
        for group in [*groups, "all"]:
            chosen = mine if group == "all" else [r for r in mine if r.dataset == group]
            per_sigma = {}
            for sigma in sorted({r.sigma for r in chosen}):
                at = [r for r in chosen if r.sigma == sigma]
                stats = {}
                for metric in METRICS:
                    m = mean_over_images(getattr(r, metric) for r in at)
                    stats[metric] = m.mean
                    if metric == "psnr":
                        stats["n_infinite"] = m.n_infinite
                stats["n_images"] = len(at)
                per_sigma[f"{sigma:g}"] = stats
            entry[group] = per_sigma
        summary[method] = entry
    return summary


def markdown_tables(summary: dict) -> str:
    """PSNR/SSIM per sigma in the layout of the paper's Table 1 (one table per image set), and
    CIEDE2000 likewise."""
    methods = list(summary)
    groups = list(dict.fromkeys(g for m in methods for g in summary[m] if g != "pattern"))
    if len(groups) == 2:  # one image set: "all" would repeat it
        groups = groups[:1]
    sigmas = list(dict.fromkeys(s for m in methods for g in groups for s in summary[m].get(g, {})))
    lines: list[str] = []
    for group in groups:
        n = max((summary[m][group][s]["n_images"] for m in methods if group in summary[m]
                 for s in summary[m][group]), default=0)
        lines += [f"### {group} ({n} images): PSNR (dB) / SSIM", ""]
        lines.append("| method | pattern | " + " | ".join(f"σ={s}" for s in sigmas) + " |")
        lines.append("|---|---|" + "---|" * len(sigmas))
        for m in methods:
            cells = []
            for s in sigmas:
                st = summary[m].get(group, {}).get(s)
                cells.append("–" if st is None else f"{_db(st['psnr'])} / {st['ssim']:.4f}")
            lines.append(f"| {m} | {summary[m]['pattern']} | " + " | ".join(cells) + " |")
        lines += ["", f"### {group}: CIEDE2000 (lower is better)", ""]
        lines.append("| method | " + " | ".join(f"σ={s}" for s in sigmas) + " |")
        lines.append("|---|" + "---|" * len(sigmas))
        for m in methods:
            cells = [
                "–" if (st := summary[m].get(group, {}).get(s)) is None
                else f"{st['ciede2000']:.3f}" for s in sigmas
            ]
            lines.append(f"| {m} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _db(v: float) -> str:
    return "inf" if math.isinf(v) else f"{v:.2f}"


def write_results(rows: Sequence[EvalRow], out_dir: str | os.PathLike) -> dict:
    """``per_image.csv``, ``summary.json`` and ``table.md`` in ``out_dir``; returns the summary."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "per_image.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["method", "pattern", "dataset", "image", "sigma", *METRICS])
        for r in rows:
            writer.writerow([r.method, r.pattern, r.dataset, r.image, f"{r.sigma:g}",
                             f"{r.psnr:.4f}", f"{r.ssim:.6f}", f"{r.ciede2000:.4f}"])
    summary = summarise(rows)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    (out_dir / "table.md").write_text(markdown_tables(summary), encoding="utf-8")
    return summary
