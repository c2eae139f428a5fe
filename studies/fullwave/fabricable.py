"""Design runs' binary layers made to keep their minimum feature, and what that costs.

    OMP_NUM_THREADS=1 python studies/fullwave/fabricable.py best-n30-f2 [best-n300-f2 ...]

A design run thresholds its densities; where they were grey that leaves specks of pillar and
slits narrower than the run's minimum feature (``--feature``), which no process at that feature
size makes. For each run (a folder of docs/results/fullwave/design) this writes
``NAME-fabricable.csv``, the binary design made to keep the feature in solid and void alike
(:func:`splitcam.design.lengthscale.with_minimum_feature`, a brush of the feature's diameter),
solves it at the run's own setting (its stack, cone, wavelengths and terms, from its
``state.json``), and appends to ``fabricable.md`` in that folder: the cells changed, the minimum
solid and void length scales before and after (imageruler, the measure the invrs-gym
leaderboard's 80 nm rule uses, where installed), and the closed-form LMMSE PSNR at the run's
target before (from the run's own spectra) and after (solved).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import torch

from splitcam.design.fullwave import FullwaveDesign
from splitcam.design.lengthscale import with_minimum_feature
from splitcam.io import write_text
from splitcam.physics.fullwave import read_design

ROOT = Path(__file__).resolve().parents[2]
DESIGNS = ROOT / "docs" / "results" / "fullwave" / "design"


def _measured(layer: np.ndarray) -> str:
    try:
        import imageruler
    except ImportError:
        return "(imageruler not installed)"
    solid, void = imageruler.minimum_length_scale(layer.astype(bool), periodic=(True, True))
    return f"{solid} / {void}"


def _psnr(design: FullwaveDesign, layer: np.ndarray) -> float:
    with torch.no_grad():
        t = design.transmission(torch.from_numpy(layer.astype(np.float64)))[0]
    return _psnr_of(design, t)


def _psnr_of(design: FullwaveDesign, transmission: torch.Tensor) -> float:
    with torch.no_grad():
        return -10.0 * math.log10(float(design.image_error(transmission.clamp_min(0.0))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+")
    args = parser.parse_args()
    for name in args.runs:
        folder = DESIGNS / name
        settings = json.loads((folder / "state.json").read_text(encoding="utf-8"))["settings"]
        binary = read_design(folder / f"{name}.csv")
        design = FullwaveDesign.from_settings(binary, settings)
        fixed = with_minimum_feature(binary, design.feature_cells).astype(np.float64)
        np.savetxt(folder / f"{name}-fabricable.csv", fixed, delimiter=",", fmt="%d")
        cell_nm = 2000.0 * settings["stack"][0] / max(binary.shape)
        rows = [
            f"# {name}: the binary design made to keep its {settings['feature'] * 1000:g} nm "
            "minimum feature",
            "",
            f"A brush of {design.feature_cells} cells ({design.feature_cells * cell_nm:g} nm) "
            "paints every pillar and every gap of `"
            f"{name}-fabricable.csv` (splitcam.design.lengthscale); solved at the run's own "
            f"setting ({settings['solver']}, {settings['terms']} terms, f/{settings['f_number']:g}"
            f" cone, {len(settings['wavelengths'])} wavelengths). Command: `OMP_NUM_THREADS=1 "
            f"python studies/fullwave/fabricable.py {name}`.",
            "",
            "| layer | cells changed | minimum solid / void (cells, imageruler) | "
            f"closed-form LMMSE PSNR at N = {settings['photons']:g} |",
            "|---|---|---|---|",
        ]
        spectra = np.loadtxt(folder / f"{name}-spectra.csv", delimiter=",", skiprows=1)
        ran = torch.from_numpy(spectra[:, 1:5].T.reshape(2, 2, -1))  # as the run solved it
        for label, layer, t in (
            ("the run's binary design", binary, ran),
            ("made fabricable", fixed, None),
        ):
            psnr = _psnr(design, layer) if t is None else _psnr_of(design, t)
            rows.append(
                f"| {label} | {int((layer != binary).sum())} of {binary.size} | "
                f"{_measured(layer)} | {psnr:.2f} dB |"
            )
            print(rows[-1], flush=True)
        write_text(folder / "fabricable.md", "\n".join(rows) + "\n")
        print((folder / "fabricable.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    main()
