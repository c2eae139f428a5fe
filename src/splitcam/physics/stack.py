"""One optical stack for every pixel: the curves all light passes through on its way to being
counted (a lens, the UV/IR-cut filter, the photodiode's quantum efficiency), applied alike to
every pixel of every sensor.

Without a stack, splitcam's sensors see light as a bare, lossless pixel does: a W pixel and a
router count every photon from 400 to 700 nm the same. A measured camera's curves (the D5100
arrays of :mod:`splitcam.patterns.measured`) already contain that camera's cut and silicon
response, so comparing them with a bare W pixel or a router gives the filters a handicap the
routers do not carry. :meth:`OpticalStack.apply` puts every sensor behind the same curves:

- **spectral sensors** (routers from full-wave solves, measured arrays): each splitter's kernel
  at each wavelength is multiplied by the stack's transmission there;
- **measured filters**, whose curves hold a camera's own stack already: the filter itself is
  estimated as the measured curve divided by the stack where the stack passes at least 30 % of
  the light (below that a fitted edge's error dominates), scaled to a peak transmission of 1,
  and then put behind the stack: the measured curve's shape wherever the stack is the
  camera's, and never a filter passing more than all of the light;
- **RGB sensors** (the ideal arrays, the splitters A-E, the (eta, chi) routers), which have no
  spectra: each colour's kernels are scaled by the stack's mean transmission over that colour's
  light (the scene basis of :mod:`splitcam.patterns.spectral`), as if the sensor treated every
  wavelength of a colour alike.

The elements (:data:`ELEMENTS`, ``splitcam study exposure --stack``):

- ``silicon``: silicon absorbing within 3 µm (:class:`~splitcam.physics.radiometry.SiliconQE`,
  M. A. Green 2008's extinction coefficients);
- ``ir-cut``: the UV/IR-cut of the Nikon D5100, estimated from the camera's own measured red
  channel (NPL, in colour-science): above 590 nm a red filter passes nearly all light, so the
  fall of the red curve there, divided by silicon's QE, is the cut's edge; a logistic edge is
  fitted to it (:func:`d5100_ir_cut`: 50 % at about 650 nm). An estimate, stated as such: the
  camera's cut itself is not published;
- ``lens``: the ISO 7589 standard camera lens transmission (colour-science's
  ``SDS_LENSES``);
- a CSV file of ``wavelength_nm,transmission`` rows: a user's own curve.

Bad curves are refused: a value outside [0, 1] or a curve that does not cover 400-700 nm.

**The scene's light** (:class:`SceneLight`, ``splitcam study exposure --illuminant``). The
scenes of the model are reflectances lit by D65 (:func:`~splitcam.patterns.spectral.scene_basis`).
Lit by another illuminant ``S``, every colour's spectrum is multiplied by ``S / D65``, scaled to
a peak of 1 over 400-700 nm so that no sensor receives more light than the model's unit (a
splitter never sends on more than arrives): a white scene then gives a bare pixel
:meth:`SceneLight.white_share` of what it collects under D65 at the same ``N``, and the
conversion to lux accounts for it (:class:`~splitcam.physics.radiometry.Camera`'s ``white``).
The light acts on every pixel of every sensor as a stack curve does, and the reconstruction
still aims at the scene's reflectance: a white-balanced image. It is not part of what a measured
curve holds, so it is never divided out of one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ..patterns import Pattern, check_pattern
from ..patterns.spectral import SpectralPattern, scene_basis
from .radiometry import ILLUMINANTS, SiliconQE

__all__ = [
    "ELEMENTS",
    "NO_STACK",
    "IRCut",
    "OpticalStack",
    "SceneLight",
    "TabulatedCurve",
    "d5100_ir_cut",
    "recorded_stack",
    "stack_of",
]

#: How a bare pixel's stack reads (:class:`OpticalStack` of no curves, :func:`recorded_stack`).
NO_STACK = "no stack"
#: The band every curve must cover (nm): the band of the sensor model.
BAND = (400.0, 700.0)
#: The grid RGB sensors' band factors are taken on (nm).
GRID = np.arange(400.0, 700.0 + 1e-9, 10.0)
#: The grid a scene light is scaled on (nm).
FINE = np.arange(400.0, 700.0 + 1e-9, 1.0)
#: Where a measured curve is divided by the stack: the stack passes at least this share.
DIVIDE_ABOVE = 0.3


@dataclass(frozen=True)
class IRCut:
    """An infrared-cut filter: transmission ``1 / (1 + exp((nm - edge_nm) / width_nm))``."""

    edge_nm: float
    width_nm: float
    source: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.edge_nm) and self.width_nm > 0):
            raise ValueError(f"an IR cut needs a finite edge and a width > 0, got {self}")

    def __call__(self, nm: Any) -> np.ndarray:
        return 1.0 / (1.0 + np.exp((np.asarray(nm, dtype=float) - self.edge_nm) / self.width_nm))

    def __str__(self) -> str:
        return f"IR cut, 50 % at {self.edge_nm:.0f} nm (width {self.width_nm:.1f} nm)"


@dataclass(frozen=True)
class TabulatedCurve:
    """A curve given at wavelengths (nm), linearly interpolated."""

    wavelengths: tuple[float, ...]
    values: tuple[float, ...]
    name: str

    def __post_init__(self) -> None:
        lams, vals = np.asarray(self.wavelengths, float), np.asarray(self.values, float)
        if lams.ndim != 1 or lams.shape != vals.shape or len(lams) < 2:
            raise ValueError(f"{self.name}: expected matching wavelengths and values, 2 or more")
        if np.any(np.diff(lams) <= 0):
            raise ValueError(f"{self.name}: wavelengths must increase")
        if lams[0] > BAND[0] or lams[-1] < BAND[1]:
            raise ValueError(
                f"{self.name} covers {lams[0]:g}-{lams[-1]:g} nm; a stack curve must cover "
                f"{BAND[0]:g}-{BAND[1]:g} nm"
            )
        if not np.all(np.isfinite(vals)) or vals.min() < 0 or vals.max() > 1:
            raise ValueError(f"{self.name}: a transmission must lie within [0, 1]")

    def __call__(self, nm: Any) -> np.ndarray:
        return np.interp(np.asarray(nm, dtype=float), self.wavelengths, self.values)

    def __str__(self) -> str:
        return self.name

    @classmethod
    def read_csv(cls, path: str | Path) -> TabulatedCurve:
        """``wavelength_nm,transmission`` rows (a header line is skipped)."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"no stack curve file {str(path)!r}")
        rows = []
        for line in path.read_text(encoding="utf-8").splitlines():
            cells = [c.strip() for c in line.split(",")]
            try:
                rows.append((float(cells[0]), float(cells[1])))
            except (ValueError, IndexError):
                if rows:  # only a first line may be a header
                    raise ValueError(f"{path}: cannot read the row {line!r}") from None
        if not rows:
            raise ValueError(f"{path}: no wavelength,transmission rows")
        lams, vals = zip(*rows, strict=True)
        return cls(tuple(lams), tuple(vals), f"{path.name}")


@lru_cache(maxsize=1)
def d5100_ir_cut() -> IRCut:
    """The D5100's UV/IR cut, estimated from its red channel (module docstring): the logistic
    edge whose product with silicon's QE best matches (least squares) the red curve's fall from
    590 to 700 nm, both scaled to 1 at 590 nm."""
    import colour

    curves = colour.MSDS_CAMERA_SENSITIVITIES["Nikon 5100 (NPL)"]
    lams = np.arange(590.0, 700.0 + 1e-9, 5.0)
    red = np.interp(lams, curves.wavelengths, curves.values[:, 0])
    red = red / red[0]
    qe = SiliconQE(3.0)(lams)
    qe = qe / qe[0]
    best = (math.inf, 0.0, 0.0)
    for edge in np.arange(600.0, 700.0 + 1e-9, 0.5):
        for width in np.arange(1.0, 40.0 + 1e-9, 0.25):
            cut = IRCut(float(edge), float(width))(lams)
            model = cut * qe / (cut[0] * qe[0])
            error = float(np.sum((model - red) ** 2))
            if error < best[0]:
                best = (error, float(edge), float(width))
    return IRCut(best[1], best[2], source="fitted to the Nikon D5100's red channel (NPL)")


def _lens() -> TabulatedCurve:
    import colour

    sd = colour.SDS_LENSES["ISO Standard Lens"]
    values = np.clip(np.asarray(sd.values, float), 0.0, 1.0)
    return TabulatedCurve(
        tuple(float(v) for v in sd.wavelengths), tuple(values), "ISO 7589 standard lens"
    )


#: The named stack elements (see the module docstring).
ELEMENTS: dict[str, Callable[[], Callable]] = {
    "silicon": lambda: SiliconQE(3.0),
    "ir-cut": d5100_ir_cut,
    "lens": _lens,
}


@dataclass(frozen=True)
class SceneLight:
    """The scenes lit by ``illuminant`` (a name of
    :data:`~splitcam.physics.radiometry.ILLUMINANTS`) in place of D65 (module docstring)."""

    illuminant: str = "D65"

    def __post_init__(self) -> None:
        if self.illuminant not in ILLUMINANTS:
            raise ValueError(
                f"unknown illuminant {self.illuminant!r}; expected one of {', '.join(ILLUMINANTS)}"
            )

    def __call__(self, nm: Any) -> np.ndarray:
        """``S / D65`` on ``nm``, scaled to a peak of 1 over 400-700 nm (1 nm steps)."""
        nm = np.asarray(nm, dtype=float)
        return self._ratio(nm) / float(self._ratio(FINE).max())

    def white_share(self) -> float:
        """The light a bare pixel collects from a white scene (one unit of each colour of the
        scene basis), against D65's at the same ``N``; 1 for D65."""
        return min(1.0, float(self(FINE) @ scene_basis(FINE).sum(axis=1)) / 3.0)

    def _ratio(self, nm: np.ndarray) -> np.ndarray:
        import colour

        spectra = colour.SDS_ILLUMINANTS
        return _on(spectra[ILLUMINANTS[self.illuminant]], nm) / _on(spectra["D65"], nm)

    def __str__(self) -> str:
        return f"scenes lit by {self.illuminant}"


def _on(sd, nm: np.ndarray) -> np.ndarray:
    return np.interp(nm, np.asarray(sd.wavelengths, float), np.asarray(sd.values, float))


@dataclass(frozen=True)
class OpticalStack:
    """Curves every pixel's light passes through; its transmission is their product. With
    ``light``, the scenes are lit by another illuminant than D65 (:class:`SceneLight`)."""

    elements: tuple[Callable, ...]
    light: SceneLight | None = None

    def __call__(self, nm: Any) -> np.ndarray:
        nm = np.asarray(nm, dtype=float)
        if nm.min() < BAND[0] - 1e-9 or nm.max() > BAND[1] + 1e-9:
            raise ValueError(f"a stack is defined on {BAND[0]:g}-{BAND[1]:g} nm")
        out = np.ones_like(nm)
        for element in self.elements:
            values = np.asarray(element(nm), dtype=float)
            if not np.all(np.isfinite(values)) or values.min() < 0 or values.max() > 1 + 1e-12:
                raise ValueError(f"{element}: a transmission must lie within [0, 1]")
            out = out * values
        return out

    def __str__(self) -> str:
        stack = " × ".join(str(e) for e in self.elements)
        if self.light is None:
            return stack or NO_STACK
        return f"{stack}, {self.light}" if stack else str(self.light)

    def weights(self, nm: Any) -> np.ndarray:
        """What each wavelength's light is multiplied by: the stack's transmission, times the
        scene light's ratio to D65 where one is set."""
        return self._lit(self(nm), nm)

    def _lit(self, transmission: np.ndarray, nm: Any) -> np.ndarray:
        """The stack's ``transmission`` on ``nm`` times the scene light's ratio, where set."""
        return transmission if self.light is None else transmission * self.light(nm)

    def band_factors(self) -> np.ndarray:
        """The stack's (and scene light's) mean weight over each colour's light (linear sRGB
        R, G, B)."""
        return self.weights(GRID) @ scene_basis(GRID)

    def apply(self, pattern: Pattern) -> Pattern:
        """``pattern`` behind this stack (module docstring), under the same name; its
        metadata records the stack.

        Raises:
            ValueError: ``pattern`` is behind a stack already (its metadata records one): a
                second stack would multiply its light by the curves twice.
        """
        pattern = check_pattern(pattern)
        if "stack" in pattern.metadata:
            raise ValueError(
                f"pattern {pattern.name!r} is behind an optical stack already "
                f"({pattern.metadata['stack']}): give the bare pattern"
            )
        spectral = pattern.metadata.get("spectral")
        if spectral is None:
            kernels = np.asarray(pattern.kernels) * self.band_factors()[None, :, None, None]
            return _renamed(pattern, kernels, self)
        lams = np.asarray(spectral["wavelengths"], float)
        kernels = np.asarray(spectral["kernels"], float)
        t = self(lams)
        w = self._lit(t, lams)
        out = kernels * w[None, :, None, None]
        for s in _measured_filters(pattern, kernels) if self.elements else []:
            out[s] = _measured_filter(kernels[s], t) * w[:, None, None]
        info = {k: v for k, v in pattern.metadata.items() if k not in ("spectral", "stack")}
        stacked = SpectralPattern(
            pattern.name,
            pattern.layout,
            lams,
            out,
            provenance=pattern.provenance,
            description=pattern.description,
            reference=pattern.reference,
            metadata={**info, "stack": str(self)},
        )
        return stacked.to_pattern()


def recorded_stack(pattern: Pattern) -> str:
    """The optical stack a pattern is behind, as :meth:`OpticalStack.apply` recorded it
    (``"no stack"`` for a bare pattern): how a network trained behind a stack is matched with
    the sensors of a study."""
    return str(pattern.metadata.get("stack", NO_STACK))


def _measured_filters(pattern: Pattern, kernels: np.ndarray) -> list[int]:
    """The splitters of a measured array (:mod:`splitcam.patterns.measured`, provenance
    ``measured filters``) that are filters: all but the bare W pixel (a kernel of 1 at every
    wavelength)."""
    if not pattern.provenance.startswith("measured filters"):
        return []
    return [s for s in range(len(kernels)) if not np.allclose(kernels[s], 1.0)]


def _measured_filter(kernel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """A measured curve ``(L, kh, kw)`` (a filter already behind a camera's stack) divided by
    the stack ``t`` where it passes at least :data:`DIVIDE_ABOVE`, scaled to peak at 1, and
    clipped to [0, 1]; where the stack passes less, the measured curve itself."""
    seen = t >= DIVIDE_ABOVE
    ratio = np.where(seen[:, None, None], kernel / np.maximum(t, 1e-12)[:, None, None], kernel)
    peak = ratio[seen].max() if seen.any() else 1.0
    return np.clip(ratio / max(peak, 1e-12), 0.0, 1.0)


def _renamed(pattern: Pattern, kernels: np.ndarray, stack: OpticalStack) -> Pattern:
    from dataclasses import replace

    return replace(pattern, kernels=kernels, metadata={**pattern.metadata, "stack": str(stack)})


def stack_of(specs: str | Sequence[str]) -> OpticalStack:
    """The stack of element names (:data:`ELEMENTS`) and CSV curve files, as a list or as the
    comma-separated text of a ``--stack`` option.

    Raises:
        ValueError: An unknown element (the message lists the known ones) or a bad curve file.
    """
    if isinstance(specs, str):
        specs = [t for t in specs.split(",") if t.strip()]
    elements = []
    for spec in specs:
        spec = spec.strip()
        if spec.lower().endswith(".csv"):
            elements.append(TabulatedCurve.read_csv(spec))
        elif spec in ELEMENTS:
            elements.append(ELEMENTS[spec]())
        else:
            raise ValueError(
                f"unknown stack element {spec!r}; known: {', '.join(ELEMENTS)}, or a CSV file "
                "of wavelength_nm,transmission rows"
            )
    return OpticalStack(tuple(elements))
