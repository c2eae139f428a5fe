"""Trained models as files: safetensors (16-bit weights) plus JSON (architecture, pattern,
provenance), small enough to ship inside the package.

A *model* is what a user reconstructs with: the network's weights, the architecture, the pattern it
was trained for (learned kernels included) and where it came from. It is made from a run by
:func:`export_model` and read by :func:`load_model`. The models shipped with splitcam live in
``splitcam/weights/models/`` and are addressed by name (``A`` ... ``E``, ``bayer``, ``A-opt``,
``D-opt``, ``D-opt-random``): ``splitcam evaluate --model D``, ``load_model("D")``.

Provenance accumulates: a run started from a model (``train --init-from D``) records that
model's provenance in its checkpoints, and exporting it adds the run as one more *segment*, so
``provenance["total_steps"]`` and ``["train_seconds"]`` count every step the weights have seen.

Weights are stored as float16 by default (half the size; the evaluated PSNR moves by far less than
0.01 dB, see ``docs/results/reproduce``); buffers that are not trained parameters (the image
statistics of the physics network) keep their dtype. Nothing is unpickled.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path
from typing import Any

import torch

from ..data.registry import portable_path
from ..io import checkpoints as ckpt_io
from ..io.domains import SRGB
from ..io.tensorfiles import paired_paths, save_pair
from ..recon.loading import MODEL_FORMAT, MODEL_VERSION, ModelError, load_model, load_network
from .recipe import MACHINE_KEYS, blend_of, replayable
from .rundir import METRICS_NAME, changes_rows, failure_of, last_metrics, metrics_rows

__all__ = [
    "blend_models",
    "described",
    "export_model",
    "model_summary",
    "portable_config",
    "provenance_of",
    "run_failure",
    "training_budget",
]

STORAGE = {"float16": torch.float16, "bfloat16": torch.bfloat16, "float32": torch.float32}


def _validation_curve(run_dir: Path, offset: int) -> list[dict[str, float]]:
    """``[{"step": s, "val_psnr_0": ..., ...}]`` of a run's log, steps shifted by ``offset``."""
    curve = []
    for row in metrics_rows(run_dir):
        vals = {k: round(v, 4) for k, v in row.items() if k.startswith("val_psnr_")}
        if vals:
            curve.append({"step": int(row.get("step", 0)) + offset, **vals})
    return curve


def _thread_history(folder: Path, final: Any, steps: int) -> list[list[int]]:
    """``[[from_step, threads], ...]`` of a run that was resumed with other thread counts, from
    its ``changes.jsonl`` (one entry when it never changed). The checkpoint itself only knows the
    last count, so without this a run trained mostly on 1 thread would claim 2."""
    changes = []
    for entry in changes_rows(folder):
        try:
            old, new = entry["changes"]["run.threads"]
            changes.append((int(entry["step"]), old, new))
        except (KeyError, TypeError, ValueError):
            continue
    changes = [c for c in changes if c[0] < steps]
    if not changes:
        return [[0, final]]
    history = [[0, changes[0][1]]]
    for step, _, new in changes:
        if history[-1][0] == step:
            history[-1][1] = new
        elif history[-1][1] != new:
            history.append([step, new])
    return history


def _device_with_threads(device: str, history: list[list[int]]) -> str:
    """``cpu (AMD EPYC, 2 threads)`` → ``cpu (AMD EPYC; 1 thread, 2 from step 11772)``."""
    base = re.sub(r",? ?\d+ threads?\)$", ")", str(device))
    parts = [f"{history[0][1]} thread{'s' if history[0][1] != 1 else ''}"]
    parts += [f"{threads} from step {step}" for step, threads in history[1:]]
    if base.endswith(")"):
        return base[:-1] + "; " + ", ".join(parts) + ")"
    return f"{base} ({', '.join(parts)})"


def provenance_of(loaded: ckpt_io.Checkpoint, run_dir: Path | None = None) -> dict[str, Any]:
    """The accumulated provenance of a checkpoint: what it was started from plus this run."""
    meta = loaded.meta
    previous = meta.get("init_from") or {}
    before = previous.get("provenance") or {"segments": [], "validation": []}
    config = meta.get("config", {})
    optim, data, run = config.get("optim", {}), config.get("data", {}), config.get("run", {})
    done = int(before.get("total_steps", 0))
    segment = {
        "run": run_dir.name if run_dir else Path(loaded.path).parent.name,
        "init_from": previous.get("name"),
        # the configuration file of this segment (a recipe's stage), where one was given
        "config_file": run.get("config_file"),
        "steps": int(meta.get("step", 0)) - int(meta.get("start_step", 0)),
        "batch_size": data.get("batch_size"),
        # patches seen by this segment, all processes together
        "patches": (int(meta.get("step", 0)) - int(meta.get("start_step", 0)))
        * int(data.get("batch_size") or 0)
        * int(meta.get("world_size", 1)),
        "patch_size": data.get("patch_size"),
        "train_seconds": round(float(meta.get("train_seconds", 0.0)), 1),
        "device": meta.get("device", "unknown"),
        "threads": run.get("threads"),
        "precision": meta.get("precision", run.get("precision")),
        "world_size": meta.get("world_size", 1),
        "data": {
            "train": portable_path(str(data.get("train", ""))),
            "images": meta.get("train_images"),
            # the sizes each photo was trained at (1: as it is; splitcam.data.downscale)
            "scales": data.get("scales", [1.0]),
        },
        "recipe": {
            "arch": config.get("network", {}).get("arch"),
            "lr": optim.get("lr"),
            "schedule": optim.get("schedule"),
            "warmup_steps": optim.get("warmup_steps"),
            "sigma": [optim.get("sigma_min"), optim.get("sigma_max")],
            "learn_pattern": config.get("pattern", {}).get("learn"),
            "pattern_init": config.get("pattern", {}).get("init"),
            "design_steps": config.get("pattern", {}).get("design_steps"),
            "time_limit_min": run.get("time_limit"),
            "divergence_factor": optim.get("divergence_factor"),
            "loss": optim.get("loss", "mse"),
            # the decay of the weight average the model is (None: the last step's weights)
            "ema": optim.get("ema"),
        },
        # the divergence guard's learning-rate scale at the end (1: it never rolled back)
        "lr_scale": meta.get("lr_scale", 1.0),
        "finished": meta.get("time"),
        # every setting it trained with but where and on what: the stage of the model's recipe
        # (splitcam.training.recipe), so the model can be trained again from its own header
        "settings": replayable(config),
    }
    folder = run_dir if run_dir is not None else Path(loaded.path).parent
    history = _thread_history(folder, run.get("threads"), segment["steps"])
    if len(history) > 1:
        segment["threads"] = history
    if str(segment["device"]).startswith("cpu") and all(isinstance(t, int) for _, t in history):
        segment["device"] = _device_with_threads(segment["device"], history)
    segments = [*before.get("segments", []), segment]
    curve = list(before.get("validation", []))
    if run_dir is not None:
        # A continued run (start_step > 0) already logs the steps of the whole.
        curve += _validation_curve(run_dir, done - int(meta.get("start_step", 0)))
    out = {
        "total_steps": done + segment["steps"],
        "train_seconds": round(sum(float(s.get("train_seconds") or 0) for s in segments), 1),
        "segments": segments,
        "validation": curve,
    }
    # trained on from a blend (blend_models), or from a model trained from one: the blend
    # stays recorded, so no recipe replays the segments as if they were one chain
    if blend := blend_of(previous):
        out["from_blend"] = blend
    return out


def export_model(
    run: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    name: str | None = None,
    storage: str = "float16",
    description: str = "",
    force: bool = False,
) -> Path:
    """Write the model of a run folder or checkpoint as ``out.safetensors`` + ``out.json``.

    Args:
        run: Run folder or checkpoint file (a run's latest, or its ``best.safetensors``).
        out: Target path (``NAME`` or ``NAME.json``).
        name: The model's name (default: the file name).
        storage: ``float16`` (default), ``bfloat16`` or ``float32`` for the trained weights.
        description: One line for tables and ``splitcam models``.
        force: Export a run that ended in failure too (:func:`run_failure`); the failure is
            recorded in the provenance.

    Returns:
        The JSON path.

    Raises:
        ModelError: A bad ``storage``, or a run that ended in failure without ``force``.
    """
    if storage not in STORAGE:
        raise ModelError(f"storage must be one of {', '.join(STORAGE)}, got {storage!r}")
    path = ckpt_io.resolve(run)
    loaded = ckpt_io.load(path)
    ckpt_io.require(loaded, "pattern", "network", "config", purpose="it cannot be exported")
    network = load_network(path).network  # validates the pattern and the network's tensors
    params = {n for n, _ in network.named_parameters()}
    tensors = {
        k: (v.to(STORAGE[storage]) if k in params else v) for k, v in network.state_dict().items()
    }
    _, meta_path = paired_paths(out)
    name = name or meta_path.stem
    run_dir = ckpt_io.run_folder_of(path)
    failure = run_failure(path) if path.name == ckpt_io.CHECKPOINT_NAME else None
    if failure and not force:
        raise ModelError(
            f"{run_dir} ended in failure ({failure}); export an earlier good state "
            f"({run_dir / ckpt_io.BEST_NAME} where it exists), or --force to export it anyway "
            f"(the failure is recorded in its provenance)"
        )
    meta = {
        "name": name,
        "description": description,  # composed from the provenance below where empty
        "network": loaded.meta["network"],
        "pattern": loaded.meta["pattern"],
        "start_pattern": loaded.meta.get("start_pattern"),
        "config": portable_config(loaded.meta["config"]),
        "storage": storage,
        "exported": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "provenance": provenance_of(loaded, run_dir),
    }
    if failure:
        meta["provenance"]["failure"] = failure
    meta["description"] = described(meta)
    return save_pair(meta_path, tensors, MODEL_FORMAT, MODEL_VERSION, meta)


def blend_models(
    start: str | os.PathLike[str],
    end: str | os.PathLike[str],
    weight: float,
    out: str | os.PathLike[str],
    *,
    name: str | None = None,
    storage: str = "float16",
    description: str = "",
) -> Path:
    """A model whose trained weights lie on the straight line between two models of one
    network and pattern (both networks of any pattern, or of one pattern with the same kernels),
    light and noise: ``(1 - weight) * start + weight * end``, written as ``out``.

    Two networks where one was trained on from the other (a stage of its recipe) sit in one
    basin of the loss, and the points between them are networks too, trading what the stage
    won against what it cost: a fine-tuned network interpolated with its start can keep most
    of the gain on the new data and lose less on the old (Wortsman et al. 2022, "Robust
    fine-tuning of zero-shot models"). The weights are blended in float32 and stored as
    ``storage``; buffers that are not trained parameters must be equal in both. The header
    is ``end``'s (pattern, config, provenance), its provenance given the segments of ``start``
    it lacks (a soup of stages counts each stage's steps), and the blend recorded in
    ``provenance["blend"]``: the weight, the storage and each end's name, description,
    checksum and provenance (its stages, or its own blend; validation curves left out), so
    ``splitcam train --recipe`` replays it: each end, then the blend
    (:func:`~splitcam.training.recipe.shipped_recipe`).

    Raises:
        ModelError: A weight outside [0, 1], a bad ``storage``, or models of different
            networks, patterns, light or noise, or buffers.
    """
    if not 0.0 <= weight <= 1.0:
        raise ModelError(f"the blend's weight must be in [0, 1], got {weight}")
    if storage not in STORAGE:
        raise ModelError(f"storage must be one of {', '.join(STORAGE)}, got {storage!r}")
    first, second = load_model(start), load_model(end)
    _check_blendable(first.meta, second.meta, start, end)
    tensors = _blended_tensors(first.network, second.network, weight, STORAGE[storage])
    if isinstance(tensors, str):
        raise ModelError(f"{start} and {end} differ in {tensors!r}, which is not trained")
    _, meta_path = paired_paths(out)
    # each end as it was made: its stages, or its own blend (whose ends hold the stages)
    ends = [
        {
            **{k: m.meta.get(k) for k in ("name", "description", "meta_sha256")},
            "provenance": _made_of(m.meta.get("provenance") or {}),
        }
        for m in (first, second)
    ]
    meta = {
        **{k: second.meta.get(k) for k in ("network", "pattern", "start_pattern", "config")},
        "name": name or meta_path.stem,
        "description": description,
        "storage": storage,
        "exported": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "provenance": _blended_provenance(first.meta, second.meta),
    }
    meta["provenance"]["blend"] = {
        "weight": weight,
        "storage": storage,
        "start": ends[0],
        "end": ends[1],
    }
    if not description:
        sha = (ends[0]["meta_sha256"] or "")[:8]
        meta["description"] = (
            f"{ends[1]['description']}; then blended weight by weight with the model "
            f"{ends[0]['name']} ({sha}): {weight:g} of these weights and {1 - weight:g} of its"
        )
    return save_pair(meta_path, tensors, MODEL_FORMAT, MODEL_VERSION, meta)


def _check_blendable(first: dict[str, Any], second: dict[str, Any], start: Any, end: Any) -> None:
    """Refuse two model headers of different networks, patterns, light or noise
    (:func:`blend_models`)."""
    (pattern, *first_on), (other, *second_on) = _trained_on(first), _trained_on(second)
    # a network of any pattern records the last one it drew: only its kind must agree
    patterns = pattern == other and (pattern == "any" or first["pattern"] == second["pattern"])
    for part, same in (
        ("network", first["network"] == second["network"]),
        ("pattern", patterns),
    ):
        if not same:
            raise ModelError(
                f"{start} and {end} are models of different {part}s: only two models of one "
                f"network and pattern can be blended"
            )
    if first_on != second_on:
        raise ModelError(
            f"{start} was trained in {first_on[0]} light with {first_on[1]} noise and {end} "
            f"in {second_on[0]} light with {second_on[1]} noise: only networks of one light "
            "and noise can be blended"
        )


def _blended_tensors(
    first: torch.nn.Module, second: torch.nn.Module, weight: float, dtype: torch.dtype
) -> dict[str, torch.Tensor] | str:
    """The state of ``second`` with every trained parameter ``(1 - weight)`` of ``first``'s
    and ``weight`` of its own (blended in float32, stored as ``dtype``), or the name of a
    buffer that is not trained and differs between the two."""
    ours, theirs = first.state_dict(), second.state_dict()
    params = {n for n, _ in second.named_parameters()}
    tensors = {}
    for key, value in theirs.items():
        if key in params:
            tensors[key] = torch.lerp(ours[key].float(), value.float(), weight).to(dtype)
        elif torch.equal(ours[key], value):
            tensors[key] = value
        else:
            return key
    return tensors


def _made_of(provenance: dict[str, Any]) -> dict[str, Any]:
    """What a blend records of one of its ends: its provenance without the validation curve,
    and without the segments where it is a blend itself (its own ends record them)."""
    left_out = {"validation", "segments"} if provenance.get("blend") else {"validation"}
    return {k: v for k, v in provenance.items() if k not in left_out}


def _blended_provenance(start: dict[str, Any], end: dict[str, Any]) -> dict[str, Any]:
    """``end``'s provenance with the segments of ``start`` it does not hold added, and the
    steps and seconds counted over them all: every step the blended weights have seen once
    (a stage and the model it started from share their first segments). No validation curve:
    the blend was never validated during training."""
    prov = dict(end.get("provenance") or {})
    segments = list(prov.get("segments", []))
    segments += [
        s for s in (start.get("provenance") or {}).get("segments", []) if s not in segments
    ]
    if segments:
        prov["segments"] = segments
        prov["total_steps"] = sum(int(s.get("steps") or 0) for s in segments)
        prov["train_seconds"] = round(sum(float(s.get("train_seconds") or 0) for s in segments), 1)
    prov["validation"] = []  # the ends' curves are not the blend's
    prov.pop("from_blend", None)  # recorded in the end's own record
    return prov


def portable_config(config: dict[str, Any]) -> dict[str, Any]:
    """A run's settings as a model file records them: the paths of :data:`MACHINE_KEYS`
    (training photos, run folder, starting point) written by
    :func:`~splitcam.data.registry.portable_path`, so no file that ships names a folder of the
    machine it trained on (they are provenance: ``--recipe`` replays a model on data given
    again)."""
    out = {section: dict(values) for section, values in config.items()}
    for key in MACHINE_KEYS:
        section, name = key.split(".")
        value = out.get(section, {}).get(name)
        if isinstance(value, str):
            out[section][name] = portable_path(value)
    return out


def described(meta: dict[str, Any]) -> str:
    """A model's one line: its ``description`` where given, else one composed from the
    header: the network, the pattern, the light and noise it was trained on, and each stage of
    its provenance (the recipe file, or the run where none is recorded, and its steps)."""
    if meta.get("description"):
        return meta["description"]
    pattern, light, noise = _trained_on(meta)
    pattern = "any pattern" if pattern == "any" else f"pattern {pattern}"
    stages = [
        f"{seg.get('config_file') or seg.get('run', '?')} ({seg.get('steps', '?')} steps)"
        for seg in (meta.get("provenance") or {}).get("segments", [])
    ]
    line = f"{meta['network']['arch']} network for {pattern}, trained in {light} light with "
    line += f"{noise} noise"
    return line + (f"; stages: {', '.join(stages)}" if stages else "")


def run_failure(checkpoint: str | os.PathLike) -> str | None:
    """Why the run of a latest checkpoint ended in failure
    (:func:`~splitcam.training.rundir.failure_of` over its log), or None: a run whose loss went
    non-finite, whose divergence guard gave up, or whose validation fell far below its start."""
    loaded_meta = ckpt_io.read_meta(checkpoint)
    run_dir = ckpt_io.run_folder_of(checkpoint)
    if run_dir is None or not (run_dir / METRICS_NAME).is_file():
        return None
    metrics = run_dir / METRICS_NAME
    return failure_of(metrics, last_metrics(metrics), float(loaded_meta.get("lr_scale", 1.0)))


def _trained_on(meta: dict[str, Any]) -> tuple[str, str, str]:
    """A model's pattern (``any`` for a network for any pattern), and the light and noise it
    was trained on (the paper's ``srgb``, ``gaussian`` where its config names none)."""
    config = meta.get("config") or {}
    trained_on = config.get("pattern", {}).get("name")
    light = (config.get("data") or {}).get("domain") or SRGB
    noise = (config.get("noise") or {}).get("model") or "gaussian"
    return ("any" if trained_on == "random" else meta["pattern"]["name"]), light, noise


def _batches(segs: list[dict[str, Any]]) -> str:
    return "/".join(str(b) for b in dict.fromkeys(g.get("batch_size") for g in segs)) or "?"


def _devices(segs: list[dict[str, Any]]) -> str:
    return ", ".join(dict.fromkeys(str(g.get("device")) for g in segs))


def training_minutes(meta: dict[str, Any]) -> str:
    """A model's training time from its provenance, CPU and GPU minutes apart (a GPU minute
    does far more steps): ``"104 min"`` on CPUs only, ``"162 min CPU + 2.3 min GPU"``. A
    segment on a ``cuda``, ``mps`` or ``xpu`` device counts as GPU time. A provenance without
    segments gives its total as plain minutes."""
    prov = meta.get("provenance", {})
    segs = prov.get("segments", [])
    if not segs:
        return f"{prov.get('train_seconds', 0) / 60:.0f} min"
    seconds = {"CPU": 0.0, "GPU": 0.0}
    for g in segs:
        gpu = str(g.get("device", "")).split(" ")[0].split(":")[0] in ("cuda", "mps", "xpu")
        seconds["GPU" if gpu else "CPU"] += float(g.get("train_seconds", 0.0))

    def minutes(s: float) -> str:
        return f"{s / 60:.0f} min" if s >= 600 else f"{s / 60:.1f} min"

    if not seconds["GPU"]:
        return minutes(seconds["CPU"])
    if not seconds["CPU"]:
        return f"{minutes(seconds['GPU'])} GPU"
    return f"{minutes(seconds['CPU'])} CPU + {minutes(seconds['GPU'])} GPU"


def training_budget(meta: dict[str, Any]) -> str:
    """One line of what a model's training cost, from its provenance: steps, batch, minutes
    and devices (``"26000 steps of batch 8, 104 min of training on cpu (1 thread)"``)."""
    prov = meta.get("provenance", {})
    segs = prov.get("segments", [])
    return (
        f"{prov.get('total_steps', '?')} steps of batch {_batches(segs)}, "
        f"{training_minutes(meta)} of training on {_devices(segs) or '?'}"
    )


def model_summary(name: str, meta: dict[str, Any]) -> dict[str, str]:
    """A row of ``splitcam models``: the model, its pattern (``any`` for a network for any
    pattern), network, the light and noise it was trained on (``srgb, gaussian``: the paper's;
    ``linear, photon``: photo-electrons in linear light), steps, batch, training time and
    devices."""
    prov = meta.get("provenance", {})
    segs = prov.get("segments", [])
    pattern, light, noise = _trained_on(meta)
    return {
        "model": name,
        "pattern": pattern,
        "network": meta["network"]["arch"],
        "trained on": f"{light}, {noise}",
        "steps": str(prov.get("total_steps", "?")),
        "batch": _batches(segs),
        "train time": training_minutes(meta),
        "device": _devices(segs),
    }
