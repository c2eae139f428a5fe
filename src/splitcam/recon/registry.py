"""The registry of reconstruction methods: from what a user types to a
:class:`~splitcam.recon.Reconstructor`.

``splitcam evaluate``, ``splitcam reconstruct`` and Python code all build their methods here, so a
name means the same thing everywhere:

- ``lmmse``: the LMMSE filters of a pattern (shipped fits for the built-in patterns, closed-form
  filters from the shipped image statistics for any other kernels, or fitted on a folder of
  training images with ``lmmse_train``);
- ``bilinear``, ``malvar2004``, ``menon2007``: classical demosaicking of the ``bayer`` pattern;
- ``demosaicnet``: the released networks of Gharbi et al. 2016 for ``bayer`` (the default) and
  ``xtrans`` (:mod:`splitcam.recon.peers`; the optional ``demosaicnet`` extra);
- a run folder or checkpoint file: a trained network with the pattern it was trained for;
- a shipped model's name (``A`` ... ``E``, ``bayer``, ``A-opt``, ``D-opt``, ``D-opt-random``; see
  :func:`splitcam.recon.loading.model_names`) or a model file: a trained network shipped with
  splitcam (``splitcam evaluate --model D``).

Every method works in a light domain (model.md §13, the ``domain`` attribute): ``lmmse``
in the one asked for (``srgb``: the shipped fit of a built-in pattern; ``linear``: the closed form
from the shipped linear image statistics), classical demosaicking in either (fixed interpolation,
no image statistics), a network in the one it was trained in (its config's ``data.domain``,
``srgb`` where the config does not say), and asking a network for another is an error.

>>> build_method("malvar2004").name
'bayer+malvar2004'

Networks are loaded by :mod:`splitcam.recon.loading`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from .. import patterns
from ..io.checkpoints import network_checkpoint, read_meta, run_folder_of
from ..io.domains import LINEAR, SRGB
from ..io.tensorfiles import meta_checksum
from ..physics.light import check_domain
from .base import NetworkReconstructor, Reconstructor
from .closed_form import closed_form_lmmse
from .demosaic import ClassicalDemosaic
from .lmmse import LMMSE, shipped_lmmse
from .loading import (
    LoadedNetwork,
    ModelError,
    check_unambiguous,
    load_model,
    load_network,
    model_names,
    resolve_model,
)
from .networks import serves_any_pattern
from .peers import DEMOSAICNET_PATTERNS, Demosaicnet

__all__ = [
    "BUILDERS",
    "DEMOSAICKING",
    "build_method",
    "build_methods",
    "build_model",
    "method_names",
    "model_domain",
    "network_kind",
    "trained_domain",
]

#: Classical demosaicking methods of the bayer pattern, by name.
DEMOSAICKING = ClassicalDemosaic.METHODS


def method_names() -> list[str]:
    """The method names :func:`build_method` knows (besides shipped models, run folders and
    checkpoints): the keys of :data:`BUILDERS`."""
    return list(BUILDERS)


def build_model(
    spec: str | os.PathLike,
    *,
    pattern: str | os.PathLike | patterns.Pattern | patterns.Given | None = None,
    tile: int | None = 512,
    precision: str = "auto",
    domain: str | None = None,
) -> NetworkReconstructor:
    """A shipped model (by name) or a model file as a reconstruction method, labelled
    ``net-<name>`` (the same for every command).

    Its ``domain`` is the light domain it was trained in (:func:`trained_domain`); ``domain``,
    if given, must be that one.

    A model for any pattern (``universal``) needs ``pattern`` (a library name, a pattern file or
    a :class:`~splitcam.patterns.Pattern`) and is labelled ``net-<name>-<pattern>``; a model of
    one pattern takes only its own (or none).

    Raises:
        ModelError: Unknown name (the message lists the shipped ones) or a damaged file.
        ValueError: A model for any pattern without ``pattern``, or a model of one pattern given
            another.
        PatternError: An unknown pattern name or a bad pattern file (the message names it).
        ValueError: ``domain`` is not the one the model was trained in.
    """
    return _model_method(spec, _given(pattern), tile, precision, domain)


def _model_method(
    spec: str | os.PathLike,
    given: patterns.Given | None,
    tile: int | None,
    precision: str,
    domain: str | None,
) -> NetworkReconstructor:
    loaded = load_model(spec)
    meta = loaded.meta
    name = meta.get("name") or Path(str(spec)).stem
    trained_in = _check_network_domain(f"net-{name}", meta.get("config"), domain)
    # Files written before their fields had a checksum: the fields themselves identify them.
    fields = "" if "meta_sha256" in meta else f":{meta_checksum(meta)}"
    return _network_method(
        loaded,
        f"net-{name}",
        given,
        own_pattern=_trained_on_one_pattern(meta.get("config")),
        identity=f"model:{name}:{meta.get('sha256', '')}{fields}",
        tile=tile,
        precision=precision,
        domain=trained_in,
    )


def trained_domain(config: dict | None) -> str:
    """The light domain a network was trained in, from its run's (or model's) saved config:
    ``data.domain``, ``srgb`` where the config does not record one."""
    data = (config or {}).get("data") or {}
    return check_domain(data.get("domain") or SRGB)


def model_domain(spec: str | os.PathLike) -> str:
    """The light domain a shipped model (by name) or model file was trained in, read from its
    JSON header (:func:`trained_domain`; the weights are not loaded).

    Raises:
        ModelError: As :func:`~splitcam.recon.loading.resolve_model`, or a header that cannot
            be read.
    """
    path = resolve_model(spec)
    try:
        config = json.loads(path.read_text(encoding="utf-8")).get("config")
        return trained_domain(config if isinstance(config, dict) else None)
    except (OSError, ValueError, AttributeError) as exc:
        raise ModelError(f"model {str(path)!r} is damaged: {exc}") from None


def _check_network_domain(label: str, config: dict | None, domain: str | None) -> str:
    """The domain of a trained network; raises if ``domain`` (when given) is another."""
    own = trained_domain(config)
    if domain is not None and check_domain(domain) != own:
        raise ValueError(
            f"{label} was trained in the {own} domain and cannot reconstruct raw images of the "
            f"{check_domain(domain)} domain (model.md §13): use --domain {own}, or a network "
            f"trained with data.domain {check_domain(domain)}"
        )
    return own


def _trained_on_one_pattern(config: dict | None) -> bool:
    """Whether a run's (or model's) saved config trained on one pattern, not ``random``."""
    name = ((config or {}).get("pattern") or {}).get("name", "")
    return str(name).strip().lower() != "random"


def _network_method(
    loaded: LoadedNetwork,
    label: str,
    given: patterns.Given | None,
    *,
    own_pattern: bool,
    identity: str,
    **options,
) -> NetworkReconstructor:
    """A trained network as a method: with its own pattern, or for a network of any pattern
    (``period`` None) with ``pattern``, labelled ``<label>-<pattern>``. Its fingerprint is
    ``identity`` (the file) followed by what else identifies its results (the pattern's values).
    A network of any pattern fine-tuned on one (``own_pattern``) reconstructs that one unless
    told another. ``options``: the reconstructor's ``tile``, ``precision`` and ``domain``."""
    if not serves_any_pattern(loaded.network) and given is not None:
        if not given.pattern.equals(loaded.pattern):
            raise ValueError(
                f"{label} reconstructs the raw images of pattern {loaded.pattern.name} only, not "
                f"of {given.label}: use a network of that pattern, the universal network or "
                f"lmmse"
            )
    if not serves_any_pattern(loaded.network) or (own_pattern and given is None):
        return NetworkReconstructor(
            loaded.network, loaded.pattern, label, fingerprint=identity, **options
        )
    if given is None:
        raise ValueError(
            f"{label} reconstructs any pattern: name the pattern of the raw images "
            f"(--pattern, a library name or a pattern file)"
        )
    resolved, name = given.pattern, given.label
    values = ",".join(f"{v:.9g}" for v in resolved.kernels.reshape(-1))
    layout = ",".join(str(v) for v in resolved.layout.reshape(-1))
    return NetworkReconstructor(
        loaded.network,
        resolved,
        f"{label}-{name}",
        any_pattern=not own_pattern,
        fingerprint=f"{identity}:{name}:{resolved.kernels.shape}:{layout}:{values}",
        **options,
    )


def network_kind(label: str, pattern: str) -> str:
    """What a network method's name says of how the network was made, without the pattern it
    reconstructs (``*`` in its place): a model for any pattern is labelled
    ``net-<model>-<pattern>`` (:func:`build_model`), a sensor's own model is often named after
    its pattern (``net-A-photon``). Networks of one kind are trained alike, so comparing two of
    them compares their patterns, not their trainings.

    >>> network_kind("net-universal-photon-rgbw", "rgbw"), network_kind("net-A-photon", "A")
    ('net-universal-photon-*', 'net-*-photon')
    >>> network_kind("net-D", "D-learned")  # the name does not say
    'net-D'
    """
    if label.endswith(f"-{pattern}"):
        return f"{label.removesuffix(pattern)}*"
    return label.replace(f"-{pattern}-", "-*-", 1)


def _is_path(spec: str | os.PathLike) -> bool:
    """A run folder or checkpoint file, as opposed to a method name."""
    text = str(spec)
    return (
        isinstance(spec, os.PathLike)
        or "/" in text
        or os.sep in text
        or text.endswith(".safetensors")
        or Path(text).exists()
    )


def _given(
    spec: str | os.PathLike | patterns.Pattern | patterns.Given | None,
) -> patterns.Given | None:
    """The pattern a caller named, read once (:func:`splitcam.patterns.read`)."""
    return None if spec is None else patterns.read(spec)


def _pattern_key(pattern: str | os.PathLike | patterns.Pattern | patterns.Given) -> str:
    """A pattern's name as typed (lower case), or a Pattern's own."""
    if isinstance(pattern, patterns.Given):
        pattern = pattern.pattern
    return (pattern.name if isinstance(pattern, patterns.Pattern) else str(pattern)).lower()


@dataclass(frozen=True)
class _Request:
    """What :func:`build_method` was asked, besides the method's name."""

    pattern: patterns.Given | None
    lmmse_train: str | os.PathLike | None
    tile: int | None
    precision: str
    progress: bool
    domain: str | None


def _build_demosaic(key: str, request: _Request) -> Reconstructor:
    return ClassicalDemosaic(key, name=f"bayer+{key}", domain=request.domain or SRGB)


def _build_demosaicnet(key: str, request: _Request) -> Reconstructor:
    return Demosaicnet(
        request.pattern.pattern if request.pattern is not None else "bayer",
        tile=request.tile,
        domain=request.domain or SRGB,
    )


def _build_lmmse(key: str, request: _Request) -> Reconstructor:
    if request.pattern is None:
        raise ValueError("method 'lmmse' needs a pattern (a name such as D, or a file)")
    resolved = request.pattern.pattern
    name = f"lmmse-{request.pattern.label}"
    if request.domain == LINEAR:
        if request.lmmse_train is not None:
            raise ValueError(
                "the LMMSE fitted on training images (--lmmse-train) is of sRGB values; in "
                "the linear domain the LMMSE is the closed form from the shipped linear "
                "image statistics: leave --lmmse-train out"
            )
        return closed_form_lmmse(resolved, name=name, domain=LINEAR)
    if request.lmmse_train is not None:
        return LMMSE.fit(resolved, request.lmmse_train, name, progress=request.progress)
    try:
        return shipped_lmmse(resolved, name)
    except FileNotFoundError:  # not a built-in's kernels: solve its filters in closed form
        return closed_form_lmmse(resolved, name=name)


def _build_network_file(spec: str | os.PathLike, request: _Request) -> Reconstructor:
    """A run folder (its best network where the run kept one) or checkpoint file: the network
    with the pattern it was trained for."""
    path = network_checkpoint(spec)
    config = read_meta(path).get("config")
    folder = run_folder_of(path)
    label = folder.name if folder is not None else path.stem
    stat = path.stat()
    return _network_method(
        load_network(path),
        label,
        request.pattern,
        own_pattern=_trained_on_one_pattern(config),
        identity=f"{path.resolve()}:{stat.st_size}:{stat.st_mtime_ns}",
        tile=request.tile,
        precision=request.precision,
        domain=_check_network_domain(label, config, request.domain),
    )


#: Method names and their builders. Shipped models (:func:`build_model`), model files, run
#: folders and checkpoints are found after these, by what the name or path is.
BUILDERS: dict[str, Callable[[str, _Request], Reconstructor]] = {
    "lmmse": _build_lmmse,
    **{key: _build_demosaic for key in ClassicalDemosaic.METHODS},
    "demosaicnet": _build_demosaicnet,
}


def build_method(
    spec: str | os.PathLike,
    *,
    pattern: str | os.PathLike | patterns.Pattern | patterns.Given | None = None,
    lmmse_train: str | os.PathLike | None = None,
    tile: int | None = 512,
    precision: str = "auto",
    progress: bool = False,
    domain: str | None = None,
) -> Reconstructor:
    """One reconstruction method from its name or a run folder / checkpoint file.

    Args:
        spec: ``lmmse``, ``bilinear``, ``malvar2004``, ``menon2007`` (:data:`BUILDERS`), a
            shipped model's name or model file, or the path of a run folder or checkpoint.
        pattern: The pattern (name, file or :class:`~splitcam.patterns.Pattern`) for ``lmmse``
            and for a network of any pattern (``universal``).
        lmmse_train: Fit the LMMSE on this folder of training images instead of using the
            shipped fit (needed for patterns other than the built-in ones).
        tile: Tile size of network reconstruction.
        precision: Network inference precision: ``auto`` (bfloat16 + channels-last where
            native), ``fp32`` or ``bf16`` (:class:`~splitcam.recon.base.NetworkReconstructor`).
        progress: Progress bars while fitting.
        domain: The light domain (``srgb`` or ``linear``) of the raw images: the LMMSE's and
            a classical demosaicker's (default ``srgb``); a network's must be this one
            (default: whichever it was trained in).

    Raises:
        ValueError: Unknown name (the message lists the valid ones), ``lmmse`` without a
            pattern, a network trained in another domain than ``domain``, or ``lmmse_train``
            in the linear domain.

    >>> import torch
    >>> lmmse = build_method("lmmse", pattern="D")
    >>> lmmse.name, lmmse.domain
    ('lmmse-D', 'srgb')
    >>> raw = torch.rand(1, 1, 16, 16, generator=torch.Generator().manual_seed(0))
    >>> lmmse.reconstruct(raw, sigma=0).shape
    torch.Size([1, 3, 16, 16])
    >>> build_method("D").name  # a shipped network, by its name
    'net-D'
    """
    key = str(spec).strip().lower()
    request = _Request(
        _given(pattern),
        lmmse_train,
        tile,
        precision,
        progress,
        check_domain(domain) if domain is not None else None,
    )
    if key in BUILDERS:
        return BUILDERS[key](key, request)
    check_unambiguous(spec, "method")
    model = spec.strip() if isinstance(spec, str) and spec.strip() in model_names() else None
    if model is None and _is_path(spec) and str(spec).endswith(".json") and Path(spec).is_file():
        model = spec
    if model is not None:
        return _model_method(model, request.pattern, tile, precision, domain)
    if _is_path(spec):
        return _build_network_file(spec, request)
    raise ValueError(
        f"unknown method {str(spec)!r}; valid: {', '.join(method_names())}, a shipped model "
        f"({', '.join(model_names()) or 'none shipped'}), or a run folder / checkpoint file"
    )


def build_methods(
    specs: Sequence[str | os.PathLike],
    *,
    patterns_for_lmmse: Sequence[str | os.PathLike | patterns.Pattern] = (),
    **options,
) -> list[Reconstructor]:
    """:func:`build_method` for each spec; ``lmmse`` expands to one method per pattern, and
    ``demosaicnet`` to one per pattern it has a network for (``bayer`` when none is given; a
    list with none of its patterns is refused, naming them)."""
    methods: list[Reconstructor] = []
    for spec in specs:
        key = str(spec).strip().lower()
        if key == "lmmse":
            if not patterns_for_lmmse:
                raise ValueError("method 'lmmse' needs at least one pattern")
            methods += [build_method(spec, pattern=p, **options) for p in patterns_for_lmmse]
        elif key == "demosaicnet":
            given = list(patterns_for_lmmse) or ["bayer"]
            served = [p for p in given if _pattern_key(p) in DEMOSAICNET_PATTERNS]
            methods += [build_method(spec, pattern=p, **options) for p in served or given[:1]]
        else:
            methods.append(build_method(spec, **options))
    return methods
