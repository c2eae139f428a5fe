"""The gate a candidate network passes before it replaces the shipped model of its name.

One rule for every way a candidate is made (a GPU relay's segment, a colour stage on a CPU, any
fine-tuning): score the candidate and the shipped model on held-out photos at the model's own
validation levels, cleanest first (σ 0 and 15 for the Gaussian models; photo-electrons for the
photon ones), and on the patterns its validation uses for a network of any pattern. The photos
are the run's validation photos (the first ``VAL_FIRST`` of those every run holds out) and the
last ``LAST_UNUSED`` of the folder, which no training or choice uses. Each is scored whole at
half its size (:data:`SCALE`), one row or column fewer where a side comes out even, so that both
sides stay odd and end part-way through every period (240x160 from a 481x321 photo, scored as
239x159). A candidate ships when the mean PSNR rises at the cleanest level and falls by no more
than ``FALL_DB`` at the noisiest.

Why half size: the training photos are JPEGs that store their chroma at half resolution (4:2:0).
Whole, their colour finer than two pixels is the decoder's interpolation, not the scene's, and a
network that learns to reproduce it scores well on them and poorly where colour edges are sharp;
at half size their chroma is as fine as their luma (``studies/colour/chroma_detail.py``,
docs/results/colour/README.md). Gates run before this rule scored the photos whole.

A candidate that is not a continuation of the shipped model of its name (another pattern to
start from, or a network of other patterns) is not gated, and its reason is kept. A model that
learns its pattern (A-opt) goes on learning it, so the patterns compared are the ones both
started from.

``splitcam models gate CANDIDATE.json ... --data DIR`` is the command.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

RISE_DB = 0.0
FALL_DB = 0.05
VAL_FIRST = 8
LAST_UNUSED = 12
#: The size the held-out photos are scored at, a fraction of their own.
SCALE = 0.5


class GateError(ValueError):
    """A candidate the gate cannot compare with the shipped model of its name."""


@dataclass
class Verdict:
    """One candidate's scores beside the shipped model's, or why it was not gated."""

    name: str
    path: Path
    photos: int = 0
    levels: list = field(default_factory=list)
    before: list[float] = field(default_factory=list)
    after: list[float] = field(default_factory=list)
    refused: str | None = None

    @property
    def change(self) -> list[float]:
        return [a - b for a, b in zip(self.after, self.before, strict=True)]

    @property
    def ships(self) -> bool:
        if self.refused is not None:
            return False
        change = self.change
        return change[0] > RISE_DB and change[-1] >= -FALL_DB


def held_out_photos(config: dict, data: Path) -> list[tuple[str, object]]:
    """The run's validation photos (the first ``VAL_FIRST`` it holds out) and the last
    ``LAST_UNUSED`` of the folder, each at :func:`gate_size`."""
    from ..data.imageio import decode_image
    from ..data.patches import list_images
    from .config import TrainConfig
    from .validation import held_out

    settings = TrainConfig.from_saved(config).override({"data.train": str(data), "data.val": None})
    validation = held_out(settings)[: settings.data.val_max_images or VAL_FIRST]
    chosen = list(dict.fromkeys([*validation, *list_images(data)[-LAST_UNUSED:]]))
    return [(p.stem, gate_size(decode_image(p))) for p in chosen]


def gate_size(image) -> object:
    """A photo as the gate scores it: its ``(H, W, 3)`` 8- or 16-bit values → a ``(3, h, w)``
    float tensor in [0, 1] at :data:`SCALE` of its size
    (:func:`~splitcam.data.patches.downscaled`), less its last row or column where that side
    comes out even."""
    from ..data.patches import downscaled

    small = downscaled(image, SCALE)
    height, width = (side - 1 + side % 2 for side in small.shape[1:])
    return small[:, :height, :width].contiguous()


def gate_levels(config: dict) -> list:
    """The model's validation levels (:func:`~splitcam.training.validation.val_levels`),
    cleanest first: by the noise variance at mid-grey, whatever the noise model."""
    from ..physics.noise import as_noise
    from .config import TrainConfig
    from .validation import val_levels

    def variance(level) -> float:
        a, b = as_noise(level).variance_coefficients()
        return a * 0.5 + b

    return sorted(val_levels(TrainConfig.from_saved(config)), key=variance)


def check_candidate(name: str, candidate, shipped) -> None:
    """Refuse a candidate that is not a continuation of the shipped model of its name: one that
    serves other patterns, or (for a network of one pattern) started from another pattern."""
    from .. import patterns
    from ..recon.networks import serves_any_pattern

    any_shipped = serves_any_pattern(shipped.network)
    if serves_any_pattern(candidate.network) != any_shipped:
        raise GateError(f"candidate {name}: it and the shipped {name} serve different patterns")
    if not any_shipped:
        start = patterns.Pattern.from_dict(candidate.meta["start_pattern"])
        shipped_start = shipped.meta.get("start_pattern")
        origin = patterns.Pattern.from_dict(shipped_start) if shipped_start else shipped.pattern
        if not start.equals(origin):
            raise GateError(
                f"candidate {name} was trained from pattern {start.name}, the shipped {name} "
                f"from {origin.name}"
            )


def mean_scores(spec, config: dict, photos, levels) -> list[float]:
    """Mean PSNR per level over the photos (and, for a network of any pattern, its validation
    patterns)."""
    from ..evaluation.protocol import mean_psnr
    from ..recon.registry import build_method

    domain = (config.get("data") or {}).get("domain") or "srgb"
    pats = config["pattern"]["val_patterns"] if config["pattern"]["name"] == "random" else [None]
    per_pattern = []
    for pattern in pats:
        method = build_method(spec, pattern=pattern, precision="fp32", domain=domain)
        scores = mean_psnr(method, photos, levels, domain=domain)
        per_pattern.append([scores[level] for level in scores])
    return [sum(col) / len(col) for col in zip(*per_pattern, strict=True)]


def held_out_score(spec: str | Path, data: Path) -> dict:
    """A model's (a shipped name or a model file) mean PSNR on the gate's held-out photos of
    ``data`` at its validation levels: ``{"photos", "scale", "levels" (labels), "psnr",
    "sha256"}``: the photos' size (:data:`SCALE`) and the checksum of the weights scored."""
    from ..physics.noise import level_label
    from ..recon.loading import load_model

    meta = load_model(spec).meta
    config = meta["config"]
    photos = held_out_photos(config, Path(data))
    levels = gate_levels(config)
    return {
        "photos": len(photos),
        "scale": SCALE,
        "levels": [level_label(level) for level in levels],
        "psnr": mean_scores(str(spec), config, photos, levels),
        "sha256": meta.get("sha256"),
    }


def candidate_name(path: Path) -> str:
    """The shipped model a candidate would replace: the file's name (``D.json`` → ``D``)."""
    return path.stem


def gate(candidates: Sequence[Path], data: Path, threads: int | None = None) -> list[Verdict]:
    """Score each candidate (an exported model's JSON) against the shipped model of its name on
    the held-out photos of ``data``."""
    import torch

    from ..recon.loading import load_model, model_names

    if threads is not None:
        torch.set_num_threads(threads)
    shipped_names = model_names()
    verdicts = []
    for path in map(Path, candidates):
        name = candidate_name(path)
        verdict = Verdict(name, path)
        verdicts.append(verdict)
        try:
            if name not in shipped_names:
                raise GateError(f"candidate {name}: no shipped model of that name")
            candidate = load_model(path)
            check_candidate(name, candidate, load_model(name))
        except GateError as err:
            verdict.refused = str(err)
            continue
        config = candidate.meta["config"]
        photos = held_out_photos(config, Path(data))
        verdict.photos = len(photos)
        verdict.levels = gate_levels(config)
        verdict.before = mean_scores(name, config, photos, verdict.levels)
        verdict.after = mean_scores(str(path), config, photos, verdict.levels)
    return verdicts


def gate_table(verdicts: Sequence[Verdict]) -> str:
    """The verdicts as a Markdown table (the refused first), with the rule in its heading."""
    from ..evaluation.tables import markdown_table
    from ..physics.noise import level_label

    fmt = " / ".join
    rows = []
    for v in sorted(verdicts, key=lambda v: v.refused is None):
        if v.refused is not None:
            rows.append([v.name, "", "", "", "", f"not gated: {v.refused}", "no", str(v.path)])
            continue
        rows.append(
            [
                v.name,
                str(v.photos),
                fmt(level_label(x) for x in v.levels),
                fmt(f"{x:.2f}" for x in v.before),
                fmt(f"{x:.2f}" for x in v.after),
                fmt(f"{x:+.2f}" for x in v.change),
                "yes" if v.ships else "no",
                str(v.path),
            ]
        )
    header = ["model", "photos", "levels", "shipped", "candidate", "change", "ships", "file"]
    heading = (
        "# Gate: the validation photos and the last 12, whole at half size; ship when the "
        f"cleanest level rises and the noisiest falls by no more than {FALL_DB} dB"
    )
    return "\n".join([heading, "", *markdown_table(header, rows)]) + "\n"


def ship(verdicts: Sequence[Verdict], ship_to: Path) -> list[str]:
    """Copy every candidate that passed (its JSON and tensors) into ``ship_to``; the names.

    Raises:
        GateError: Two or more candidates of one name passed (one would silently replace the
            other): nothing is copied, and the message names them, to ship one alone.
    """
    from ..io.tensorfiles import paired_paths

    passed: dict[str, list[str]] = {}
    for v in verdicts:
        if v.ships:
            passed.setdefault(v.name, []).append(str(v.path))
    for name, paths in passed.items():
        if len(paths) > 1:
            raise GateError(
                f"{len(paths)} candidates for {name} pass ({', '.join(paths)}): gate the one "
                "to ship alone with --ship"
            )
    shipped = []
    for v in verdicts:
        if v.ships:
            for src in paired_paths(v.path):
                shutil.copyfile(src, Path(ship_to) / src.name)
            shipped.append(v.name)
    return shipped
