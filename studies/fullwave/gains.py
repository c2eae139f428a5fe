"""What each design verified at the converged setting gains over the leaderboard design it
started from, against exposure, beside what doubling the break-even with the D5100 RGBW asks.

    python studies/fullwave/gains.py [--out docs/results/fullwave/gains.png]

Each design's ``verify/NAME-f2-fmmax797-spectra.csv`` (``verify_cone.sh solve``: 797 terms, the
f/2 cone, six wavelengths) and the leaderboard design's solve at the same setting; the
closed-form LMMSE PSNR (read noise 2 e-) with every pixel behind silicon and the IR cut, as the
exposure study scores the pixel (``verify_design.py`` computes the same numbers at five
exposures). The mark at N = 44 is the gain the router's network needs there for its crossover
with the RGBW to move from 22 to 44 (the network scores of the exposure answer).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from verify_design import psnr_at, spectra  # noqa: E402  (the verification's own)

from splitcam.physics.stack import stack_of  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "docs" / "results" / "fullwave" / "design"
START = ROOT / "docs" / "results" / "fullwave" / "angles" / "patterns" / "best-f2-centre-6wl.toml"
#: (run, legend): the fabricable designs, then the two that ignore the 80 nm rule.
DESIGNS = (
    ("best-n30-fab-f2", "made for N = 30, keeps 80 nm"),
    ("best-n300-fab-f2", "made for N = 300, keeps 80 nm"),
    ("best-n30-f2", "made for N = 30, 10 nm features (not fabricable)"),
    ("best-n300-f2", "made for N = 300, 10 nm features (not fabricable)"),
)
ANSWER = ROOT / "docs" / "results" / "exposure" / "answer" / "rn2" / "exposure.json"


def psnr_curve(path: Path, photons: np.ndarray) -> np.ndarray:
    """Closed-form LMMSE PSNR of the spectra in ``path`` at each exposure, behind the stack."""
    lams, t = spectra(path)
    return np.asarray(psnr_at(lams, t, photons, optics=stack_of("silicon,ir-cut")))


def needed_gain(at: str = "46.4") -> float:
    """The RGBW's network PSNR minus the leaderboard design's (computed kernels) at ``at``."""
    results = json.loads(ANSWER.read_text(encoding="utf-8"))["results"]
    net = "net-universal-photon-"
    return results[net + "rgbw-d5100"][at]["psnr"] - results[net + "best-f2-computed"][at]["psnr"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs/results/fullwave/gains.png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    photons = np.geomspace(3, 3000, 25)
    start = psnr_curve(START, photons)
    fig, ax = plt.subplots(figsize=(8, 5.2))
    for (run, label), style in zip(DESIGNS, ("-", "-", "--", "--"), strict=True):
        path = DESIGN / run / "verify" / f"{run}-f2-fmmax797-spectra.csv"
        if not path.is_file():
            print(f"{path}: not solved yet (verify_cone.sh solve {run}); left out")
            continue
        gain = psnr_curve(path, photons) - start
        ax.semilogx(photons, gain, style, label=label)
        best = int(np.argmax(gain))
        print(
            f"{run}: gain at N 30 {np.interp(30, photons, gain):+.3f} dB, largest "
            f"{gain[best]:+.3f} at N {photons[best]:.0f}"
        )
    need = needed_gain()
    ax.plot(
        [44],
        [need],
        "k*",
        markersize=12,
        label=f"needed at N = 44 to double the break-even ({need:+.2f} dB, network)",
    )
    ax.axhline(0, color="0.5", linewidth=0.8)
    ax.set_xlabel("photo-electrons N of a lossless pixel (white scene)")
    ax.set_ylabel("gain over the leaderboard design (dB)")
    ax.set_title(
        "Designs from the leaderboard design, solved at 797 terms, f/2 cone,\n"
        "behind silicon + IR cut; closed-form LMMSE, read noise 2 e-",
        fontsize=10,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    fig.tight_layout()
    fig.savefig(args.out, dpi=130)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
