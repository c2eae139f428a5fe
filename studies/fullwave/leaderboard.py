"""The leaderboard's best design by fmmax at the leaderboard's settings: does the geometry land on
its band efficiencies when the formulation is the other one?

    OMP_NUM_THREADS=1 python studies/fullwave/leaderboard.py --formulation JONES_DIRECT \
        --terms 1000 --wavelengths 433,467,533,567,633,667 --out FILE.json

The design (``experiments/fullwave/designs/best-240325.csv``: 0.699 µm of Si3N4 in vacuum on
SiO2, monitor 2.8 µm deep) at each wavelength, normal incidence, both polarisations averaged, by
:func:`solvers.fmmax_quadrants` (``splitcam optics rcwa --solver fmmax-jones`` solves the same;
fmmax must be installed: ``pip install 'splitcam[fmmax]'``). The band
efficiency of a colour is the mean, over that band's wavelengths, of the transmission into its
own pixels (blue where 433 nm peaks, red where 667 nm peaks, green the other two), as the
leaderboard defines it. Wavelengths can be split over several runs and their JSON files merged
by ``--merge``; with ``--pattern NAME`` the merged spectra are written as a spectral pattern
file (``--pattern-out FILE``), as ``splitcam optics rcwa`` writes its own.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from solvers import DESIGN, fmmax_quadrants  # noqa: E402

from splitcam.physics.fullwave import RouterDesign, band_efficiencies, read_design  # noqa: E402

#: The leaderboard's numbers (blue / green / red band efficiency, 1000 terms).
LEADERBOARD = (0.656, 0.594, 0.551)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--formulation", default="JONES_DIRECT")
    parser.add_argument("--terms", type=int, default=1000)
    parser.add_argument("--wavelengths", default="433,467,533,567,633,667")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--merge", type=Path, nargs="+", help="JSON files of earlier runs")
    parser.add_argument("--pattern", help="with --merge: write the spectra as this pattern")
    parser.add_argument("--pattern-out", type=Path, help="the pattern file (default NAME.toml)")
    args = parser.parse_args()
    if args.merge:
        runs = [json.loads(p.read_text()) for p in args.merge]
        quads = {float(k): np.array(v) for r in runs for k, v in r["quadrants"].items()}
        lams = sorted(quads)
        t = np.stack([quads[lam] for lam in lams], axis=-1)  # (2, 2, L)
        b = band_efficiencies(t, lams)
        ours = (b["blue"], b["green"], b["red"])
        print("band efficiency blue / green / red: {:.3f} / {:.3f} / {:.3f}".format(*ours))
        print("leaderboard: {:.3f} / {:.3f} / {:.3f}".format(*LEADERBOARD))
        if args.pattern:
            _write_pattern(args.pattern, lams, t, runs, args.pattern_out)
        return
    design = RouterDesign(read_design(DESIGN / "best-240325.csv"), thickness=0.699, depth=2.8)
    result = {"formulation": args.formulation, "quadrants": {}, "seconds": {}}
    for lam in (float(v) for v in args.wavelengths.split(",")):
        t0 = time.perf_counter()
        q, n = fmmax_quadrants(design, lam, args.terms, args.formulation)
        result["terms"] = n
        result["quadrants"][f"{lam:g}"] = np.asarray(q).tolist()
        result["seconds"][f"{lam:g}"] = round(time.perf_counter() - t0, 1)
        print(f"{lam:g} nm: {np.round(q, 3).tolist()} ({result['seconds'][f'{lam:g}']} s)")
        if args.out:
            args.out.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")


def _write_pattern(name: str, lams, t, runs: list[dict], out: Path | None) -> None:
    """The merged spectra as a spectral pattern file (checked, then read back)."""
    from splitcam.patterns.files import save_transmission

    info = {
        "provenance": f"full-wave (RCWA by fmmax, {runs[0]['formulation']}, "
        f"{runs[0]['terms']} terms, normal incidence)",
        "description": "metasurface router best-240325.csv (the invrs-gym leaderboard's best "
        "Bayer sorter): pitch 1 µm, 0.699 µm of Si3N4 in vacuum on SiO2, monitor 2.8 µm deep; "
        "normal incidence",
        "reference": "studies/fullwave/leaderboard.py",
    }
    path = save_transmission(out or Path(f"{name}.toml"), name, lams, np.clip(t, 0.0, None), **info)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
