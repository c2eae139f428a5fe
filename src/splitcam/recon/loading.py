"""Loading trained networks for reconstruction: from a run (folder or checkpoint) or a model
(a shipped model's name, or a model file written by ``splitcam models export``).

Both give a :class:`LoadedNetwork`: the network (float32, eval mode), the pattern it
reconstructs (learned kernels included) and the file's metadata. The file formats are
:mod:`splitcam.io.checkpoints` and :mod:`splitcam.io.tensorfiles`; writing a model is training's
(:func:`splitcam.training.models.export_model`). The shipped models live in
:data:`splitcam.io.weights.MODELS_DIR` and are addressed by name (``A`` ... ``E``, ``bayer``,
``A-opt``, ``D-opt``, ``D-opt-random``, ``universal``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, NamedTuple

import torch
from torch import nn

from ..io import weights
from ..io.checkpoints import EMA_PREFIX, CheckpointError, load, load_module, require
from ..io.tensorfiles import load_pair, paired_paths
from ..patterns import Pattern
from .networks import UniversalReconNet, build_network

__all__ = [
    "MODEL_FORMAT",
    "MODEL_VERSION",
    "LoadedNetwork",
    "ModelError",
    "check_unambiguous",
    "load_model",
    "load_network",
    "model_names",
    "model_serves_any_pattern",
    "resolve_model",
]

#: The model file format (``NAME.safetensors`` + ``NAME.json``).
MODEL_FORMAT = "splitcam-model"
#: 2: the JSON fields carry their checksum (``meta_sha256``); 1: files from before it, read
#: too, fingerprinted by their fields instead.
MODEL_VERSION = 2


class ModelError(ValueError):
    """A model name or file that cannot be used; the message says why (and the valid names)."""


class LoadedNetwork(NamedTuple):
    """A trained network with the pattern it reconstructs and its file's metadata."""

    network: nn.Module
    pattern: Pattern
    meta: dict[str, Any]


def load_network(path: str | os.PathLike, device: str | torch.device = "cpu") -> LoadedNetwork:
    """The network of a run folder (its latest checkpoint) or checkpoint file (also a run's
    ``best.safetensors``), with the pattern it had at that step (a learned pattern as fixed
    kernels), in eval mode.

    Raises:
        CheckpointError: Missing or damaged checkpoint, or a header without pattern or network.
    """
    loaded = load(path)
    where = loaded.path
    require(loaded, "pattern", "network", purpose="it cannot be loaded as a trained system")
    try:
        pattern = Pattern.from_dict(loaded.meta["pattern"], source=where)
        network = build_network(loaded.meta["network"])
    except (ValueError, KeyError, TypeError) as exc:  # PatternError is a ValueError too
        what = f"its header lacks {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CheckpointError(f"checkpoint {where!r}: {what}") from None
    # A run that keeps an average of its weights (optim.ema) is used by that average.
    prefix = EMA_PREFIX if loaded.section(EMA_PREFIX) else "model"
    load_module(network, loaded, prefix=prefix, child="network")
    return LoadedNetwork(network.to(device).eval(), pattern, loaded.meta)


def model_names() -> list[str]:
    """Names of the models shipped with splitcam (sorted)."""
    if not weights.MODELS_DIR.is_dir():
        return []
    return sorted(p.stem for p in weights.MODELS_DIR.glob("*.json"))


def check_unambiguous(spec: str | os.PathLike[str], flag: str) -> None:
    """Refuse a bare name that is both a shipped model and a file or folder here (``D`` when
    ``./D`` is a run folder, as ``splitcam sweep`` names them): either reading would silently
    use something the user did not mean. The message shows both and how to name each."""
    text = str(spec)
    if isinstance(spec, str) and text in model_names() and Path(text).exists():
        kind = "run folder" if Path(text).is_dir() else "file"
        raise ModelError(
            f"{flag} {text} is ambiguous: the shipped model {text} and the {kind} ./{text}; "
            f"write ./{text} for the {kind}, or --model {text} for the shipped model"
        )


def resolve_model(spec: str | os.PathLike[str]) -> Path:
    """A shipped model's name, or a model file (either file of the pair) → its JSON path.

    Raises:
        ModelError: Neither a shipped name nor an existing model file; the message lists the
            shipped names.
    """
    text = str(spec)
    if text in model_names():
        return weights.MODELS_DIR / f"{text}.json"
    _, meta_path = paired_paths(text)
    if meta_path.is_file():
        return meta_path
    shipped = ", ".join(model_names()) or "none shipped"
    raise ModelError(f"unknown model {text!r}; shipped models: {shipped} (or a model .json file)")


def model_serves_any_pattern(spec: str | os.PathLike[str]) -> bool:
    """Whether a shipped model or model file is a network for any pattern (``universal``), read
    from its JSON header (the weights are not loaded).

    Raises:
        ModelError: As :func:`resolve_model`, or a header that cannot be read.
    """
    path = resolve_model(spec)
    try:
        arch = json.loads(path.read_text(encoding="utf-8"))["network"]["arch"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ModelError(f"model {str(path)!r} is damaged: {exc}") from None
    return arch == UniversalReconNet.arch


def load_model(spec: str | os.PathLike[str], device: str | torch.device = "cpu") -> LoadedNetwork:
    """A shipped model (by name) or a model file: its network (float32, eval mode), pattern
    (learned kernels included) and metadata (provenance, config, description).

    Raises:
        ModelError: Unknown name, damaged or inconsistent files.
    """
    meta_path = resolve_model(spec)
    tensors, meta, _ = load_pair(
        meta_path, MODEL_FORMAT, MODEL_VERSION, "splitcam model", ModelError, unchecked_before=2
    )
    try:
        pattern = Pattern.from_dict(meta["pattern"], source=str(meta_path))
        network = build_network(meta["network"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ModelError(f"model {str(meta_path)!r} is damaged: {exc}") from None
    own = network.state_dict()
    if set(own) != set(tensors) or any(own[k].shape != tensors[k].shape for k in own):
        raise ModelError(f"model {str(meta_path)!r}: its tensors do not fit its architecture")
    network.load_state_dict({k: v.to(own[k].dtype) for k, v in tensors.items()})
    for key, value in network.state_dict().items():
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise ModelError(f"model {str(meta_path)!r} holds NaN or infinite values in {key!r}")
    return LoadedNetwork(network.to(device).eval(), pattern, meta)
