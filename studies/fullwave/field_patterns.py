"""Spectral patterns of both routers at the centre and the corner of a camera's field, from the
angles study's solves (``studies/fullwave/angles.py``): the six leaderboard wavelengths, fmmax
Jones-direct at 793 terms, normal incidence and an f/2 lens's cone with its chief ray at 0°, 15°
and 25° (the centre, middle and corner; tilted along the design's diagonal).

    python studies/fullwave/field_patterns.py [--angles docs/results/fullwave/angles]
        [--out docs/results/fullwave/angles/patterns]

Six wavelengths, two per band, integrate the scene basis coarsely (splitcam.patterns.spectral),
so these patterns are for comparing the centre with the corner of one design at one setting,
not for replacing the 10-20 nm patterns shipped in the library. Each file is a pattern for
``--pattern`` (``splitcam study exposure --patterns FILE,...``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from splitcam.patterns.files import save_transmission

SETTINGS = {
    "normal": ("convergence", "{design}/797", "normal incidence"),
    "f2-centre": ("angles", "{design}/797/f2.0/cra0", "f/2 cone, chief ray 0°"),
    "f2-corner": ("angles", "{design}/797/f2.0/cra25", "f/2 cone, chief ray 25° (diagonal)"),
    "f2-middle": ("angles", "{design}/797/f2.0/cra15", "f/2 cone, chief ray 15° (diagonal)"),
}
DESIGNS = {
    "zou": "zou2022-16x16.csv (Zou et al. 2022)",
    "best": "best-240325.csv (the invrs-gym leaderboard's best)",
}
WAVELENGTHS = (433.0, 467.0, 533.0, 567.0, 633.0, 667.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--angles", type=Path, default=Path("docs/results/fullwave/angles"))
    parser.add_argument("--out", type=Path, default=Path("docs/results/fullwave/angles/patterns"))
    args = parser.parse_args()
    data = json.loads((args.angles / "angles.json").read_text(encoding="utf-8"))
    args.out.mkdir(parents=True, exist_ok=True)
    for design, what in DESIGNS.items():
        for setting, (section, key, words) in SETTINGS.items():
            entry = data[section].get(key.format(design=design))
            if entry is None:
                print(f"{design} {setting}: not solved yet")
                continue
            t = np.clip(np.asarray(entry["transmission"], dtype=float), 0.0, None)
            name = f"{design}-{setting}-6wl"
            path = save_transmission(
                args.out / f"{name}.toml",
                name,
                list(WAVELENGTHS),
                t,
                provenance="full-wave (RCWA by fmmax, JONES_DIRECT, 793 terms), six wavelengths",
                description=f"metasurface router {what}; {words}; band efficiencies "
                f"{entry['blue']:.3f} / {entry['green']:.3f} / {entry['red']:.3f}",
                reference="studies/fullwave/angles.py, studies/fullwave/field_patterns.py",
            )
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
