"""The paper's evaluation protocol (model.md §7), the one path every score goes through.

Every method sees the same scenes and the same noise: the raw image of each scene is simulated
with the method's pattern (:func:`splitcam.physics.simulate`: float64 sensor, evaluation noise
seeded by the image name and sigma), reconstructed through the
:class:`~splitcam.recon.Reconstructor` interface, clamped and scored on 8-bit images
(:func:`score`). Training validation, ``splitcam evaluate`` and the LMMSE screening all call
:func:`simulate_and_reconstruct` and :func:`score`, so a run's logged validation PSNR is what
``evaluate`` reports for the same images and sigmas.

:func:`evaluate` checks every argument before any work, appends each result to
``per_image.csv`` as soon as it is computed, and continues an interrupted evaluation of the same
settings where it stopped.

Every step takes a light domain (model.md §13). ``srgb`` is the paper's protocol: the test
image's 8-bit values / 255 are the light. In ``linear`` the scene is decoded to linear radiance
with the sRGB transfer function before the sensor and the noise, the method (which must be of
the linear domain, :func:`~splitcam.recon.base.method_domain`) estimates radiance, and the
estimate is encoded back to sRGB, clipped and scored against the original 8-bit image with the
same metrics.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from ..data.imageio import write_image
from ..io import write_text
from ..io.domains import SRGB
from ..io.locks import folder_held
from ..patterns import Pattern, save
from ..physics.light import check_domain, decode_scene, encode_estimate
from ..physics.noise import NoiseModel, as_noise, check_level, level_heading, level_label
from ..physics.sensor import SplitterSensor
from ..physics.system import simulate
from ..recon.base import Reconstructor, method_domain
from ..viz.zoom import check_region, zoom_figure
from .metrics import SSIM_WINDOW, compute_all, mean_over_images
from .tables import CSV_NAME, EvalRow, append_rows, read_rows, result_label, write_summary

__all__ = [
    "Zoom",
    "check_method_domains",
    "evaluate",
    "method_fingerprint",
    "mean_psnr",
    "parse_zoom",
    "score",
    "score_images",
    "simulate_and_reconstruct",
]

Images = Sequence[tuple[str, torch.Tensor]]
SETTINGS_NAME = "evaluation.json"


def check_method_domains(methods: Sequence[Reconstructor], domain: str) -> str:
    """``domain`` checked, and every method of it (:func:`~splitcam.recon.base.method_domain`).

    Raises:
        ValueError: An unknown domain, or a method of another one (the message names it).
    """
    domain = check_domain(domain)
    wrong = [f"{m.name} ({method_domain(m)})" for m in methods if method_domain(m) != domain]
    if wrong:
        raise ValueError(
            f"method(s) of another light domain than this evaluation's ({domain}): "
            f"{', '.join(wrong)}; a method reconstructs raw images of the domain it was made "
            f"for (model.md §13)"
        )
    return domain


def simulate_and_reconstruct(
    method: Reconstructor,
    sensor: SplitterSensor,
    image_name: str,
    rgb: torch.Tensor,
    sigma: float | NoiseModel,
    *,
    domain: str = SRGB,
) -> torch.Tensor:
    """One step of the protocol: the noisy raw image of ``rgb`` (:func:`splitcam.physics.simulate`)
    and the method's reconstruction, clamped to [0, 1]. ``sigma`` is a Gaussian sigma or a
    photon-model :class:`~splitcam.physics.noise.Exposure`. In the ``linear`` domain the sensor
    sees the scene's linear radiance and the estimate is encoded back to sRGB display values
    before the clamp (model.md §13); the output is always of display values.

    Raises:
        ValueError: The method is not of ``domain``.

    Shape:
        - rgb: ``(3, H, W)``; output ``(3, H, W)`` float32 in [0, 1], on the CPU.
    """
    domain = check_method_domains([method], domain)
    raw = simulate(sensor, decode_scene(rgb[None], domain), image_name, sigma)
    with torch.no_grad():
        estimate = method.reconstruct(raw, sigma)[0].float()
        return encode_estimate(estimate, domain).clamp(0, 1).cpu()


def score(pred: torch.Tensor, rgb: torch.Tensor, *, crop: int = 0) -> dict[str, float]:
    """PSNR, SSIM and CIEDE2000 of a reconstruction on 8-bit images (model.md §7)."""
    return compute_all(pred, rgb.cpu(), crop=crop)


def score_images(
    method: Reconstructor,
    images: Images,
    sigmas: Sequence[float],
    *,
    crop: int = 0,
    sensor: SplitterSensor | None = None,
    domain: str = SRGB,
) -> Iterator[tuple[str, float, torch.Tensor, dict[str, float]]]:
    """``(image name, sigma, reconstruction, scores)`` for every image at every sigma, in the
    light domain ``domain`` (:func:`simulate_and_reconstruct`)."""
    domain = check_method_domains([method], domain)
    sensor = sensor if sensor is not None else SplitterSensor(method.pattern)
    for sigma in sigmas:
        level = check_level(sigma)
        for name, rgb in images:
            pred = simulate_and_reconstruct(method, sensor, name, rgb, level, domain=domain)
            yield name, level, pred, score(pred, rgb, crop=crop)


def mean_psnr(
    method: Reconstructor,
    images: Images,
    sigmas: Sequence[float],
    *,
    sensor: SplitterSensor | None = None,
    domain: str = SRGB,
) -> dict[float, float]:
    """Mean PSNR per sigma over ``images`` (infinite PSNRs left out, as in the tables); a noise
    level may also be a photon-model :class:`~splitcam.physics.noise.Exposure`. ``domain``:
    the light domain (:func:`simulate_and_reconstruct`)."""
    scores: dict = {check_level(s): [] for s in sigmas}
    for _, sigma, _, values in score_images(method, images, sigmas, sensor=sensor, domain=domain):
        scores[sigma].append(values["psnr"])
    return {s: mean_over_images(v).mean for s, v in scores.items()}


@dataclass(frozen=True)
class Zoom:
    """An image to draw side-by-side zoomed crops of, the region (``None``: the most detailed
    one) and the noise level (``None``: every level evaluated)."""

    image: str
    region: tuple[int, int, int] | None = None
    sigma: float | None = None


_ZOOM_SYNTAX = "expected a zoom as IMAGE[:TOP,LEFT,SIZE][@SIGMA]"


def parse_zoom(spec: str) -> Zoom:
    """``"name"``, ``"name:top,left,size"``, either followed by ``"@sigma"`` (the paper's
    Fig. 4: ``"kodim05@10"``)."""
    head, at, level = spec.partition("@")
    sigma = None
    if at:
        try:
            sigma = float(level)
        except ValueError:
            raise ValueError(f"{_ZOOM_SYNTAX}, got {spec!r}") from None
        if not sigma >= 0:
            raise ValueError(f"expected a zoom noise level >= 0, got {spec!r}")
    name, _, region = head.partition(":")
    if not name:
        raise ValueError(f"{_ZOOM_SYNTAX}, got {spec!r}")
    if not region:
        return Zoom(name, None, sigma)
    try:
        top, left, size = (int(v) for v in region.split(","))
    except ValueError:
        raise ValueError(f"{_ZOOM_SYNTAX}, got {spec!r}") from None
    if top < 0 or left < 0 or size < 1:
        raise ValueError(f"expected a zoom region with TOP, LEFT >= 0 and SIZE >= 1, got {spec!r}")
    return Zoom(name, (top, left, size), sigma)


def _check_zooms(
    zooms: Sequence[Zoom], datasets: Sequence[tuple[str, Images]]
) -> dict[str, list[Zoom]]:
    """Every zoom names an image of the datasets and its region lies inside it; the zooms of
    each image."""
    shapes = {name: tuple(rgb.shape[1:]) for _, images in datasets for name, rgb in images}
    out: dict[str, list[Zoom]] = {}
    for zoom in zooms:
        if zoom.image not in shapes:
            known = ", ".join(list(shapes)[:8]) + (", ..." if len(shapes) > 8 else "")
            raise ValueError(
                f"--zoom names image {zoom.image!r}, which is not among the "
                f"images evaluated ({known})"
            )
        if zoom.region is not None:
            check_region(zoom.region, shapes[zoom.image])
        out.setdefault(zoom.image, []).append(zoom)
    return out


def _zoom_at(zooms: list[Zoom], sigma: float | NoiseModel) -> Zoom | None:
    """The zoom of an image at one noise level: one naming that level, else one naming none."""
    level = as_noise(sigma)
    exact = [z for z in zooms if z.sigma is not None and as_noise(z.sigma) == level]
    return (exact or [z for z in zooms if z.sigma is None] or [None])[0]


def method_fingerprint(method: Reconstructor, crop: int, domain: str = SRGB) -> str:
    """What a stored result depends on besides its key: the method's kind, its pattern's kernels
    and the border crop, bfloat16 inference where a network runs in it, and a light domain other
    than srgb. A result is reused on resume only if this is unchanged."""
    from ..recon.base import fast_precision

    pattern: Pattern = method.pattern
    items = [type(method).__name__, pattern.to_dict(), crop, getattr(method, "fingerprint", None)]
    if fast_precision(getattr(method, "precision", "fp32"), "cpu"):
        items.append("bf16")  # float32 results keep the fingerprint they had before
    if domain != SRGB:  # srgb results keep the fingerprint they had before
        items.append(f"domain:{domain}")
    text = json.dumps(
        items,
        sort_keys=True,
        default=str,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def evaluate(
    methods: Sequence[Reconstructor],
    datasets: Sequence[tuple[str, Images]],
    sigmas: Sequence[float | NoiseModel],
    out: str | os.PathLike | None = None,
    *,
    save_images: bool = False,
    zoom_images: Sequence[str | Zoom] | None = None,
    crop: int = 0,
    progress: bool = True,
    resume: bool = True,
    zoom_only: bool = False,
    zoom_sigmas: Sequence[float] | None = None,
    domain: str = SRGB,
    rescore_changed: bool = False,
) -> list[EvalRow]:
    """Score every method on every image at every noise level, writing results to ``out`` as it
    goes. A noise level is the paper's Gaussian sigma (8-bit units) or a photon-model
    :class:`~splitcam.physics.noise.Exposure` (model.md §11; rows labelled ``N<photons>``);
    the exposures of one evaluation share their sensor settings (read noise, full well, ADC).

    Writes ``per_image.csv`` (a row as soon as it is computed), then ``summary.json``,
    ``table.md``, each method's pattern under ``patterns/`` and ``evaluation.json`` (what the
    results depend on). With ``save_images``, the reconstructions go under ``images/`` and, for
    each image in ``zoom_images`` (default: the first image of each dataset), a side-by-side
    zoom of all methods (the paper's Figs. 4, 5, 7, 8) under ``zoom/``: ``"kodim05:200,300,96"``
    zooms on the 96-pixel square at row 200, column 300; a bare name on the image's most
    detailed region; ``"kodim05@10"`` only at sigma 10 (default: at every level). ``crop``
    removes that many border pixels before scoring (0, the paper's convention, by default).
    ``zoom_only`` draws the zoom figures without writing every reconstruction; ``zoom_sigmas``
    limits the zoom figures to those noise levels.

    ``domain``: the light domain (model.md §13), ``srgb`` (the paper's protocol) or
    ``linear`` (:func:`simulate_and_reconstruct`); every method must be of it. Each row records
    it, and in the summary and tables a method's results of the linear domain are labelled
    ``<method> (linear)``, so one folder keeps the results of both domains apart.

    With ``resume`` (default), results already in ``out/per_image.csv`` for the same method (same
    weights, pattern kernels and inference precision), image set and crop, image, level and
    domain are kept and not recomputed: an interrupted evaluation continues where it stopped,
    and a second evaluation into the same folder replaces only the rows it recomputes (a row is
    keyed by method, dataset, which names its crop, ``NAME-256px``, image, level and domain).
    A method of a name whose results there were made with other weights, pattern or
    precision is refused, unless ``rescore_changed``: then its old rows are dropped and it is
    scored again (a model shipped since), the other methods' rows kept.

    Raises:
        ValueError: No method, duplicate method names, a method of another light domain, a bad
            sigma, crop or domain, exposures with different sensor settings, a zoom that
            names an unknown image or a region outside it, or a method whose weights or pattern
            differ from those of the folder's results under its name (without
            ``rescore_changed``); all checked before any work.
    """
    domain, sigmas, sensor_settings = _check_settings(methods, sigmas, crop, domain)
    zoom = _zoom_plan(zoom_images, datasets)
    _check_image_sizes(datasets, crop)
    fingerprints = {
        result_label(m.name, domain): method_fingerprint(m, crop, domain) for m in methods
    }
    out_dir = Path(out) if out is not None else None
    with _results_folder(out_dir):
        done: dict[tuple, EvalRow] = {}
        others: list[EvalRow] = []
        if out_dir is not None:
            done, others = _start_folder(
                out_dir,
                methods,
                fingerprints,
                sensor_settings,
                crop,
                resume=resume,
                rescore_changed=rescore_changed,
            )
        run = _Run(
            methods=methods,
            sensors={m.name: SplitterSensor(m.pattern) for m in methods},
            domain=domain,
            crop=crop,
            out_dir=out_dir,
            done=done,
            zooms=zoom,
            save_images=save_images,
            zoom_only=zoom_only,
            zoom_sigmas=zoom_sigmas,
        )
        jobs = [
            (dataset, name, rgb, sigma)
            for dataset, images in datasets
            for name, rgb in images
            for sigma in sigmas
        ]
        run.bar = _progress_bar(len(jobs) * len(methods), len(done)) if progress else None
        try:
            for dataset, image_name, rgb, sigma in jobs:
                _evaluate_job(run, dataset, image_name, rgb, sigma)
        finally:
            if run.bar is not None:
                run.bar.close()
        if out_dir is not None:
            # The folder keeps every result this evaluation did not recompute: other methods', and
            # this one's at other images, crops, levels or domains.
            made = {row.key for row in run.rows}
            kept = [row for row in done.values() if row.key not in made]
            write_summary([*others, *kept, *run.rows], out_dir)
        return run.rows


@contextlib.contextmanager
def _results_folder(out_dir: Path | None) -> Iterator[None]:
    """The results folder, held by this evaluation alone while it writes there (a second
    evaluation into it is refused at once: both would continue its ``per_image.csv``). A folder
    that the evaluation creates, and that holds no result when it fails (a crash or a refusal),
    is removed: nothing half-made is left behind."""
    created = out_dir is not None and not out_dir.exists()
    held = folder_held(out_dir, "evaluation") if out_dir is not None else contextlib.nullcontext()
    try:
        with held:
            yield
    except BaseException:
        csv_path = out_dir / CSV_NAME if out_dir is not None else None
        if created and out_dir.is_dir() and not (csv_path.is_file() and read_rows(csv_path)):
            shutil.rmtree(out_dir, ignore_errors=True)
        raise


def _check_settings(
    methods: Sequence[Reconstructor],
    sigmas: Sequence[float | NoiseModel],
    crop: int,
    domain: str,
) -> tuple[str, list[float | NoiseModel], dict | None]:
    """The domain, noise levels and photon sensor settings of an evaluation, checked with its
    methods and crop.

    Raises:
        ValueError: No method, duplicate method names, a method of another light domain, a bad
            or no sigma, exposures with different sensor settings or a bad crop.
    """
    if not methods:
        raise ValueError("expected at least one method to evaluate")
    names = [m.name for m in methods]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(
            f"expected distinct method names, got {', '.join(twice)} more than once (a network "
            "is named by the name stored in its model file, not by the file's name)"
        )
    domain = check_method_domains(methods, domain)
    levels = [check_level(s) for s in sigmas]
    if not levels:
        raise ValueError("expected at least one sigma")
    sensor_settings = _sensor_settings(levels)
    if isinstance(crop, bool) or not isinstance(crop, int) or crop < 0:
        raise ValueError(f"expected crop as an integer >= 0, got {crop!r}")
    return domain, levels, sensor_settings


def _zoom_plan(
    zoom_images: Sequence[str | Zoom] | None, datasets: Sequence[tuple[str, Images]]
) -> dict[str, list[Zoom]]:
    """The zooms of each image (:func:`_check_zooms`): those given (specs parsed), by default
    the first image of each dataset."""
    zooms = [z if isinstance(z, Zoom) else parse_zoom(z) for z in zoom_images or ()]
    if zoom_images is None:
        zooms = [Zoom(images[0][0]) for _, images in datasets if images]
    return _check_zooms(zooms, datasets)


def _check_image_sizes(datasets: Sequence[tuple[str, Images]], crop: int) -> None:
    """Every image is large enough for SSIM's window after the border crop.

    Raises:
        ValueError: Images too small (the first five named).
    """
    need = SSIM_WINDOW + 2 * crop  # what SSIM's window needs after the border crop
    small = [
        f"{dataset}/{name} ({rgb.shape[-1]}x{rgb.shape[-2]})"
        for dataset, images in datasets
        for name, rgb in images
        if min(rgb.shape[-2:]) < need
    ]
    if small:
        raise ValueError(
            f"{len(small)} image(s) smaller than {need}x{need} pixels, the least SSIM needs with "
            f"a {crop}-pixel border crop: {', '.join(small[:5])}{' ...' if len(small) > 5 else ''}"
            f"; remove them from the folder"
        )


def _start_folder(
    out_dir: Path,
    methods: Sequence[Reconstructor],
    fingerprints: dict[str, str],
    sensor_settings: dict | None,
    crop: int,
    *,
    resume: bool,
    rescore_changed: bool = False,
) -> tuple[dict[tuple, EvalRow], list[EvalRow]]:
    """Prepare ``out_dir`` for an evaluation: the results kept from an earlier one (with
    ``resume``, :func:`_previous_rows`) rewritten as the CSV and summary, ``evaluation.json``
    and the methods' patterns written. Returns the rows reused and those of other methods."""
    out_dir.mkdir(parents=True, exist_ok=True)
    done, others, other_prints = (
        _previous_rows(out_dir, fingerprints, sensor_settings, crop, rescore_changed)
        if resume
        else ({}, [], {})
    )
    # Rewrite the CSV with the rows kept (this evaluation's so far, and those of other
    # methods, which stay), then append: the file holds every result that still applies.
    write_summary([*others, *done.values()], out_dir)
    write_text(
        out_dir / SETTINGS_NAME,
        json.dumps(
            {
                "crop": crop,
                "fingerprints": {**other_prints, **fingerprints},
                "photon_sensor": sensor_settings,
            },
            indent=2,
        )
        + "\n",
    )
    (out_dir / "patterns").mkdir(exist_ok=True)
    for method in methods:
        save(method.pattern, out_dir / "patterns" / f"{method.name}.json")
    return done, others


def _progress_bar(total: int, initial: int):
    """A progress bar over every reconstruction, ``initial`` of them already done."""
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, unit="recon", desc="evaluate", dynamic_ncols=True)


@dataclass
class _Run:
    """One evaluation under way: its methods and their sensors, settings, output folder (or
    ``None``), the rows reused from an earlier run (by key), the zooms of each image, the
    progress bar (or ``None``) and the rows so far, in order."""

    methods: Sequence[Reconstructor]
    sensors: dict[str, SplitterSensor]
    domain: str
    crop: int
    out_dir: Path | None
    done: dict[tuple, EvalRow]
    zooms: dict[str, list[Zoom]]
    save_images: bool
    zoom_only: bool
    zoom_sigmas: Sequence[float] | None
    bar: Any = None
    rows: list[EvalRow] = field(default_factory=list)


def _evaluate_job(
    run: _Run, dataset: str, image_name: str, rgb: torch.Tensor, sigma: float | NoiseModel
) -> None:
    """Every method on one image at one noise level: rows reused where the run has them (and
    no zoom needs the reconstruction), else computed; then the images and zoom written."""
    this_zoom = _zoom_at(run.zooms.get(image_name, []), sigma)
    zoomed = (
        (run.save_images or run.zoom_only)
        and this_zoom is not None
        and (run.zoom_sigmas is None or sigma in run.zoom_sigmas)
    )
    outputs = {}
    for method in run.methods:
        key = (method.name, dataset, image_name, level_label(sigma), run.domain)
        if key in run.done and not zoomed:
            run.rows.append(run.done[key])
            continue
        outputs[method.name] = _evaluate_method(run, method, key, rgb, sigma)
    if run.out_dir is not None and outputs and (run.save_images or zoomed):
        _save_images(
            run.out_dir,
            dataset,
            image_name,
            sigma,
            rgb,
            outputs if run.save_images else {},
            this_zoom if zoomed else None,
            zoom_outputs=outputs,
            domain=run.domain,
        )


def _evaluate_method(
    run: _Run, method: Reconstructor, key: tuple, rgb: torch.Tensor, sigma: float | NoiseModel
) -> tuple[torch.Tensor, dict[str, float]]:
    """One method's reconstruction and scores of the job ``key`` (method, dataset, image,
    level, domain): its row added to the run and, if new, to ``per_image.csv`` and the
    progress bar's count."""
    _, dataset, image_name, level, domain = key
    pred = simulate_and_reconstruct(
        method, run.sensors[method.name], image_name, rgb, sigma, domain=domain
    )
    scores = score(pred, rgb, crop=run.crop)
    fields = {"sigma": 0.0, **as_noise(sigma).row_fields()}
    row = EvalRow(
        method.name, method.pattern.name, dataset, image_name, **fields, **scores, domain=domain
    )
    run.rows.append(row)
    new = key not in run.done
    if run.out_dir is not None and new:
        append_rows(run.out_dir / CSV_NAME, [row])
    if run.bar is not None:
        if new:
            run.bar.update(1)
        run.bar.set_postfix_str(
            f"{dataset}/{image_name} {level_heading(level)} "
            f"{result_label(method.name, domain)} "
            f"{scores['psnr']:.2f} dB",
            refresh=False,
        )
    return pred, scores


def _sensor_settings(levels: Sequence[float | NoiseModel]) -> dict | None:
    """The photon-model sensor settings shared by the exposures among ``levels`` (everything
    but the exposure itself), or None without exposures.

    Raises:
        ValueError: Exposures with different settings (their rows could not be told apart).
    """
    settings = {
        json.dumps(shared, sort_keys=True)
        for shared in (as_noise(e).sensor_settings() for e in levels)
        if shared is not None
    }
    if len(settings) > 1:
        raise ValueError(
            "expected the exposures of one evaluation to share their sensor settings (read "
            "noise, full well, gain, bits, shot noise); evaluate the others into another folder"
        )
    return json.loads(settings.pop()) if settings else None


def _previous_rows(
    out_dir: Path,
    fingerprints: dict[str, str],
    sensor_settings: dict | None = None,
    crop: int = 0,
    rescore_changed: bool = False,
) -> tuple[dict[tuple, EvalRow], list[EvalRow], dict[str, str]]:
    """What an earlier evaluation left in ``out_dir``: its rows that this one reuses (same
    method fingerprint, and for photon-model rows the same sensor settings), the rows of
    methods this one does not evaluate (kept, with their fingerprints), and those fingerprints.
    A method evaluated again with other weights, pattern or precision is refused (with
    ``rescore_changed``, its rows are dropped: neither reused nor kept). Methods are
    told apart by their result labels (``fingerprints``' keys, :func:`result_label`): a method's
    results of the other light domain are another method's here, and stay.

    Raises:
        ValueError: The folder's results were scored with another crop, or other photon sensor
            settings, than this evaluation's: one table cannot hold both; or they hold results
            of a method of this evaluation's name made with other weights, pattern or
            precision.
    """
    csv_path, settings_path = out_dir / CSV_NAME, out_dir / SETTINGS_NAME
    if not (csv_path.is_file() and settings_path.is_file()):
        return {}, [], {}
    try:
        settings = json.loads(settings_path.read_text(encoding="utf-8"))
        before = dict(settings["fingerprints"])
    except (OSError, ValueError, KeyError, TypeError):
        return {}, [], {}
    rows = read_rows(csv_path)
    if rows and settings.get("crop", 0) != crop:
        raise ValueError(
            f"{out_dir} holds results scored with a {settings.get('crop', 0)}-pixel border crop; "
            f"this evaluation crops {crop}: choose another --out, or --restart to discard them"
        )
    same_sensor = settings.get("photon_sensor") == sensor_settings
    changed = sorted(
        label
        for label, now in fingerprints.items()
        if before.get(label) not in (None, now) and any(row.label == label for row in rows)
    )
    if changed and not rescore_changed:
        raise ValueError(
            f"{out_dir} holds results of {', '.join(changed)} made with other weights, another "
            f"pattern or another precision: --update to score it again (the other methods' "
            f"results kept), evaluate this one under another name (a model file or run folder "
            f"of another name) or into another --out, or --restart to discard the folder's "
            f"results"
        )
    others = [row for row in rows if row.label not in fingerprints]
    if not same_sensor and any(r.photons for r in others):
        raise ValueError(
            f"{out_dir} holds photon-model results of other sensor settings (read noise, full "
            f"well, ADC): choose another --out, or --restart to discard them"
        )
    reused = {
        row.key: row
        for row in rows
        if row.label in fingerprints
        and before.get(row.label) == fingerprints[row.label]
        and (not row.photons or same_sensor)
    }
    prints = {m: f for m, f in before.items() if m not in fingerprints}
    return reused, others, prints


def _save_images(
    out_dir: Path,
    dataset: str,
    image: str,
    sigma: float | NoiseModel,
    rgb: torch.Tensor,
    outputs: dict,
    zoom: Zoom | None,
    zoom_outputs: dict | None = None,
    domain: str = SRGB,
) -> None:
    """Write each reconstruction in ``outputs`` and, with ``zoom``, the side-by-side zoom of
    ``zoom_outputs`` (default: ``outputs``); file names of the linear domain end in
    ``_linear``."""
    safe = image.replace("/", "_")
    noise = as_noise(sigma)
    suffix, title = noise.file_label(), noise.describe()
    if domain != SRGB:
        suffix, title = f"{suffix}_{domain}", f"{title}, {domain} light"
    for name, (pred, _) in outputs.items():
        path = out_dir / "images" / name / dataset / f"{safe}_{suffix}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_image(path, pred)
    if zoom is not None:
        zoom_figure(
            rgb,
            zoom_outputs if zoom_outputs is not None else outputs,
            out_dir / "zoom" / f"{dataset}_{safe}_{suffix}.png",
            region=zoom.region,
            title=f"{dataset}/{image}, {title}",
        )
