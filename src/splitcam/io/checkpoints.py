"""Checkpoints: one safetensors file that rebuilds a run alone, plus a readable JSON copy of its
metadata.

``RUN/checkpoint.safetensors`` holds every tensor (network, sensor, optimiser moments, RNG
states) and, in the safetensors header, a JSON document with the configuration, the current
pattern (learned kernels included), the network architecture, the step and the optimiser's
hyper-parameters. Nothing is ever unpickled. Files are written to a temporary name, flushed and
renamed, so a killed process leaves either the previous checkpoint or the new one, never a
damaged one.
"""

from __future__ import annotations

import errno
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from . import atomic_path, write_text

__all__ = [
    "BEST_NAME",
    "CHECKPOINT_NAME",
    "EMA_PREFIX",
    "Checkpoint",
    "CheckpointError",
    "load",
    "load_module",
    "network_checkpoint",
    "read_meta",
    "require",
    "resolve",
    "run_folder_of",
    "save",
    "which_checkpoint",
]

FORMAT = "splitcam-checkpoint"
VERSION = 1
CHECKPOINT_NAME = "checkpoint.safetensors"
#: The run's weights at its best validation so far (weights and header only: what export and
#: reconstruction need, not what a resume needs), kept beside the latest checkpoint, so a
#: resume that goes wrong never takes the good weights with it. Evaluation and reconstruction of
#: a run folder use it (:func:`network_checkpoint`); export takes the file itself
#: (``models export RUN/best.safetensors``).
BEST_NAME = "best.safetensors"
#: The section of a checkpoint that holds the average of the network's weights, when the run
#: keeps one (``optim.ema``, :mod:`splitcam.training.ema`): ``ema/network.<name>``. Readers that
#: use a run's network for reconstruction prefer it to the trained ``model/`` weights.
EMA_PREFIX = "ema"


class CheckpointError(ValueError):
    """A checkpoint is missing, damaged, or does not fit what it is loaded into."""


@dataclass
class Checkpoint:
    """What a checkpoint file holds."""

    meta: dict[str, Any]
    tensors: dict[str, torch.Tensor]
    path: str = ""
    """The file it was read from (for messages)."""

    def section(self, prefix: str) -> dict[str, torch.Tensor]:
        """Tensors under ``prefix/`` with the prefix removed."""
        cut = len(prefix) + 1
        return {k[cut:]: v for k, v in self.tensors.items() if k.startswith(prefix + "/")}


def resolve(path: str | os.PathLike) -> Path:
    """A run folder or a checkpoint file → the checkpoint file (of a folder, its latest)."""
    path = Path(path)
    return path / CHECKPOINT_NAME if path.is_dir() else path


def network_checkpoint(path: str | os.PathLike) -> Path:
    """The checkpoint whose network a reader of ``path`` reconstructs with: a file is itself; a
    run folder means its best network (:data:`BEST_NAME`, the weights of its best validation)
    where the run kept one, else its latest checkpoint. Give ``RUN/checkpoint.safetensors`` for
    the latest."""
    path = Path(path)
    if path.is_dir() and (path / BEST_NAME).is_file():
        return path / BEST_NAME
    return resolve(path)


def run_folder_of(path: str | os.PathLike) -> Path | None:
    """The run folder a checkpoint file belongs to (the latest or the best), or None for a
    checkpoint file of another name."""
    path = Path(path)
    return path.parent if path.name in (CHECKPOINT_NAME, BEST_NAME) else None


def which_checkpoint(path: str | os.PathLike, *, best: bool = False) -> str | None:
    """For a run folder: which checkpoint a reader of the folder uses, from which step, and
    where the other is; None for a checkpoint file or a folder without a checkpoint.

    Args:
        path: A run folder (or a file: None).
        best: The reader uses :func:`network_checkpoint` (evaluation and reconstruction: the
            best where kept), not the latest (export, ``--init-from``).
    """
    path = Path(path)
    latest_path = path / CHECKPOINT_NAME
    if not path.is_dir() or not latest_path.is_file():
        return None
    latest = read_meta(latest_path)
    best_path = path / BEST_NAME
    kept = read_meta(best_path) if best_path.is_file() else None
    if kept is None or kept.get("step") == latest.get("step"):
        return f"{path}: using its latest checkpoint, step {latest.get('step')}"
    best_text = (
        f"best validation, {kept.get('best_val', float('nan')):.2f} dB at step {kept.get('step')}"
    )
    if best:
        return (
            f"{path}: using its {best_text} ({best_path}); its latest checkpoint, step "
            f"{latest.get('step')}, is {latest_path} (give that file to use it)"
        )
    return (
        f"{path}: using its latest checkpoint, step {latest.get('step')}; its {best_text}, is "
        f"kept in {best_path} (give that file to use it)"
    )


def save(path: str | os.PathLike, meta: dict[str, Any], tensors: dict[str, torch.Tensor]) -> Path:
    """Write ``tensors`` and ``meta`` atomically to ``path`` (and ``meta`` to ``path.json``)."""
    from safetensors import SafetensorError
    from safetensors.torch import save_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "version": VERSION, **meta}
    text = json.dumps(meta, indent=2)
    # safetensors refuses shared or non-contiguous storage; clone into plain CPU tensors.
    plain = {k: v.detach().to("cpu").contiguous().clone() for k, v in tensors.items()}
    with atomic_path(path) as tmp:
        try:
            save_file(plain, str(tmp), metadata={"splitcam": text})
        except SafetensorError as exc:  # how safetensors reports a failed write (a full disk)
            raise OSError(errno.EIO, str(exc)) from None
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
    write_text(path.with_suffix(".json"), text + "\n")
    return path


def _parse_header(path: Path, header: dict[str, str]) -> dict[str, Any]:
    """The splitcam meta of a safetensors header, or CheckpointError naming ``path``."""
    try:
        meta = json.loads(header["splitcam"])
    except (KeyError, json.JSONDecodeError):
        raise CheckpointError(f"{str(path)!r} is not a splitcam checkpoint") from None
    if not isinstance(meta, dict):
        raise CheckpointError(f"{str(path)!r} is not a splitcam checkpoint")
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise CheckpointError(
            f"{str(path)!r}: expected {FORMAT} version {VERSION}, got "
            f"{meta.get('format')} version {meta.get('version')}"
        )
    return meta


def _open(path: str | os.PathLike, tensors: bool) -> Checkpoint:
    from safetensors import safe_open

    path = resolve(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint at {str(path)!r}")
    try:
        with safe_open(str(path), framework="pt") as fh:
            header = fh.metadata() or {}
            values = {k: fh.get_tensor(k) for k in fh.keys()} if tensors else {}  # noqa: SIM118 - not a dict
    except Exception as exc:  # safetensors raises its own error types for damaged files
        raise CheckpointError(
            f"checkpoint {str(path)!r} is damaged or not a safetensors file ({exc})"
        ) from None
    return Checkpoint(meta=_parse_header(path, header), tensors=values, path=str(path))


def read_meta(path: str | os.PathLike) -> dict[str, Any]:
    """The header of a checkpoint (step, config, ...) without reading its tensors: what a
    sweep's ``status`` needs, at the cost of a few kilobytes instead of the whole file.

    Raises:
        CheckpointError: as :func:`load`, except that damage past the header goes unnoticed.
    """
    return _open(path, tensors=False).meta


def load(path: str | os.PathLike) -> Checkpoint:
    """Read a checkpoint file (or the one in a run folder).

    Raises:
        CheckpointError: Missing, truncated or otherwise damaged file, or not a splitcam
            checkpoint.
    """
    ckpt = _open(path, tensors=True)
    for key, tensor in ckpt.tensors.items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise CheckpointError(
                f"checkpoint {ckpt.path!r} holds NaN or infinite values in {key!r} (the run "
                f"diverged, or the file is damaged); use an earlier checkpoint"
            )
    return ckpt


def require(ckpt: Checkpoint, *keys: str, purpose: str = "") -> None:
    """Refuse a checkpoint whose header lacks any of ``keys``, naming the file and the keys
    (instead of a ``KeyError`` later on)."""
    missing = [k for k in keys if k not in ckpt.meta]
    if missing:
        raise CheckpointError(
            f"checkpoint {ckpt.path!r} has no {' or '.join(repr(k) for k in missing)} in its "
            f"header{', so ' + purpose if purpose else ''}"
        )


def load_module(
    module: torch.nn.Module, ckpt: Checkpoint, prefix: str = "model", child: str = ""
) -> None:
    """Load ``module``'s parameters and buffers, refusing any mismatch with a clear message.

    ``child`` selects a submodule's entries of the saved state (e.g. ``"network"``).
    """
    state = ckpt.section(prefix)
    if child:
        cut = len(child) + 1
        state = {k[cut:]: v for k, v in state.items() if k.startswith(child + ".")}
    own = module.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    wrong = sorted(k for k in set(own) & set(state) if own[k].shape != state[k].shape)
    if missing or unexpected or wrong:
        details = []
        if missing:
            details.append(f"missing {', '.join(missing[:4])}")
        if unexpected:
            details.append(f"unexpected {', '.join(unexpected[:4])}")
        if wrong:
            k = wrong[0]
            details.append(
                f"{k} has shape {tuple(state[k].shape)} in the checkpoint, "
                f"{tuple(own[k].shape)} here"
            )
        raise CheckpointError("checkpoint belongs to another architecture: " + "; ".join(details))
    module.load_state_dict(state)
