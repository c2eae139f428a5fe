"""A new user's battery: what the README, docs/commands.md and the results pages tell a user to
try, run on a fresh clone, each case checked for the right result, not only an exit status.

    SPLITCAM_DATA=DIR python studies/battery/battery.py [--out docs/results/battery]
        [--only NAME ...] [--work /tmp/splitcam-battery]

The clone is ``git clone`` of this repository's HEAD (what a user gets; nothing untracked), and
every command runs as ``python -m splitcam`` from that clone's sources, one thread, in a folder
of its own. ``DIR`` holds the datasets (``splitcam data download kodak24 mcmaster train --to
DIR``); the training cases use ``DIR/train``.

Each case is one or more commands and checks against an independent expectation (a file's
size against its input's, a value recomputed from the files, a number that must not move). A
case is **ok** when every check holds, **traceback** when any command printed a Python
traceback, and **wrong** when a check failed (a wrong result, a wrong exit status, lost data or
an unclear message: the detail says which). The table (``OUT/README.md``) lists every case
with its commands, verdict and seconds, and ``OUT/battery.json`` the same as data.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CASES: list[tuple[str, str, Callable]] = []


def case(name: str, what: str):
    def wrap(fn):
        CASES.append((name, what, fn))
        return fn

    return wrap


class Wrong(AssertionError):
    pass


class Tracebacks(Exception):
    pass


class Shell:
    """Runs ``splitcam ...`` (and other commands) in a case's folder from the clone."""

    def __init__(self, clone: Path, folder: Path, data: str | None) -> None:
        self.clone, self.folder = clone, folder
        self.env = {
            **os.environ,
            "PYTHONPATH": str(clone / "src"),
            "OMP_NUM_THREADS": "1",
            "MKL_NUM_THREADS": "1",
            "MPLBACKEND": "Agg",
        }
        self.env.pop("SPLITCAM_MIRROR", None)
        if data:
            self.env["SPLITCAM_DATA"] = data
        else:
            self.env.pop("SPLITCAM_DATA", None)
        self.log: list[str] = []

    def __call__(self, command: str, *, code: int | None = 0, timeout: int = 600):
        line = (
            command.replace("splitcam ", "python -m splitcam ", 1)
            if command.startswith("splitcam ")
            else command
        )
        data = self.env.get("SPLITCAM_DATA")
        # Logged as a user would type it: the data folder by its variable, not this machine's path.
        self.log.append(command.replace(data, "$SPLITCAM_DATA") if data else command)
        result = subprocess.run(
            line,
            shell=True,
            cwd=self.folder,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        out = result.stdout + result.stderr
        if "Traceback (most recent call last)" in out:
            raise Tracebacks(f"`{command}`: {out.strip().splitlines()[-1][:200]}")
        if code is not None and result.returncode != code:
            raise Wrong(
                f"`{command}` exited {result.returncode}, expected {code}: "
                f"{(result.stderr.strip() or result.stdout.strip()).splitlines()[-1:]}"
            )
        return result

    def path(self, name: str) -> Path:
        return self.folder / name


def check(condition: bool, message: str) -> None:
    if not condition:
        raise Wrong(message)


def one_line_error(result, *words: str) -> None:
    lines = [ln for ln in result.stderr.strip().splitlines() if ln.strip()]
    check(len(lines) >= 1, "no message on stderr")
    text = result.stderr.lower()
    for word in words:
        check(word.lower() in text, f"the error does not say {word!r}: {lines[-1][:160]}")


def read_png(path: Path) -> np.ndarray:
    from splitcam.data.imageio import read_image

    return np.asarray(read_image(path))


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape:
        raise Wrong(f"shapes differ: {a.shape} against {b.shape}")
    return float(10 * np.log10(1.0 / np.mean((a - b) ** 2)))


def photo(sh: Shell, name: str = "photo.png", size=(53, 67)) -> Path:
    """A photograph with odd sides (53 x 67: part-way through every period) as a user has."""
    from PIL import Image
    from skimage import data

    img = data.astronaut()[100 : 100 + size[0], 180 : 180 + size[1]]
    path = sh.path(name)
    Image.fromarray(img).save(path)
    return path


def image_of(path: Path) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGB"), np.float64) / 255.0


def table_rows(path: Path) -> list[str]:
    return [ln for ln in path.read_text().splitlines() if ln.startswith("|")]


# --------------------------------------------------------------------------------- patterns
@case("patterns-list", "the design measures of every pattern")
def _(sh):
    out = sh("splitcam patterns").stdout
    for name in ("A", "B", "C", "D", "E", "bayer"):
        check(f"| {name} " in out, f"pattern {name} missing from the list")


@case("patterns-show", "a pattern drawn (paper Fig. 3)")
def _(sh):
    sh("splitcam patterns show D --out d.png")
    check(image_of(sh.path("d.png")).std() > 0.05, "d.png is blank")


@case("patterns-export-roundtrip", "a pattern exported, read back: the same kernels")
def _(sh):
    sh("splitcam patterns export D --out mine.toml")
    from splitcam import patterns

    a, b = patterns.get("D"), patterns.get(str(sh.path("mine.toml")))
    check(np.allclose(np.asarray(a.kernels), np.asarray(b.kernels)), "kernels changed")
    sh("splitcam patterns show mine.toml --out mine.png")


@case("patterns-export-keeps-a-file", "exporting over a user's file never replaces it")
def _(sh):
    sh.path("mine.toml").write_text("# my notes\n")
    r = sh("splitcam patterns export D --out mine.toml", code=None)
    check(sh.path("mine.toml").read_text() == "# my notes\n", "the user's file was replaced")
    check(r.returncode != 0, "exit 0 though nothing was written")


@case("patterns-measured", "a filter array of measured camera curves")
def _(sh):
    sh("splitcam patterns show bayer-d5100 --out b.png")
    check(sh.path("b.png").exists(), "no chart")


@case("patterns-unknown", "an unknown pattern: one line naming the choices")
def _(sh):
    r = sh("splitcam patterns show Q --out q.png", code=1)
    one_line_error(r, "Q")
    check(not sh.path("q.png").exists(), "a file was written for a bad pattern")


# --------------------------------------------------------------------------------- simulate
@case("simulate-odd", "a raw image of an odd-sized photo has the photo's size")
def _(sh):
    photo(sh)
    sh("splitcam simulate photo.png --pattern D --sigma 10 --out raw.png")
    raw = np.asarray(__import__("PIL.Image", fromlist=["Image"]).open(sh.path("raw.png")))
    check(raw.shape[:2] == (53, 67), f"raw is {raw.shape}, the photo 53 x 67")


@case("simulate-user-pattern", "a user's pattern file simulates like its source pattern")
def _(sh):
    photo(sh)
    sh("splitcam patterns export B --out mine.toml")
    sh("splitcam simulate photo.png --pattern mine.toml --sigma 0 --out a.png")
    sh("splitcam simulate photo.png --pattern B --sigma 0 --out b.png")
    check(sh.path("a.png").read_bytes() == sh.path("b.png").read_bytes(), "raw images differ")


@case("simulate-bad-sigma", "a negative sigma: refused, nothing written")
def _(sh):
    photo(sh)
    r = sh("splitcam simulate photo.png --pattern D --sigma -3 --out raw.png", code=None)
    check(r.returncode != 0, "exit 0 with sigma -3")
    check(not sh.path("raw.png").exists(), "raw.png written")


# ------------------------------------------------------------------------------ reconstruct
@case("reconstruct-network", "the shipped D network on an odd raw image beats its LMMSE")
def _(sh):
    photo(sh)
    sh("splitcam simulate photo.png --pattern D --sigma 10 --out raw.png")
    sh("splitcam reconstruct --model D --raw raw.png --sigma 10 --out net.png")
    sh("splitcam reconstruct --method lmmse --pattern D --raw raw.png --sigma 10 --out lm.png")
    truth = image_of(sh.path("photo.png"))
    net, lm = psnr(image_of(sh.path("net.png")), truth), psnr(image_of(sh.path("lm.png")), truth)
    check(net > lm > 20, f"network {net:.2f} dB, LMMSE {lm:.2f} dB")


@case("reconstruct-universal-user-pattern", "the network for any pattern on a user's pattern")
def _(sh):
    photo(sh)
    sh("splitcam patterns export C --out mine.toml")
    sh("splitcam reconstruct --model universal --pattern mine.toml --image photo.png --out u.png")
    sh("splitcam reconstruct --method lmmse --pattern mine.toml --image photo.png --out l.png")
    truth = image_of(sh.path("photo.png"))
    u, lm = psnr(image_of(sh.path("u.png")), truth), psnr(image_of(sh.path("l.png")), truth)
    check(u > lm, f"universal {u:.2f} dB under LMMSE {lm:.2f} dB")


@case("reconstruct-demosaicnet", "the GPU-trained peer on a Bayer raw image (extra installed)")
def _(sh):
    photo(sh)
    r = sh(
        "splitcam reconstruct --method demosaicnet --pattern bayer --image photo.png --out dm.png",
        code=None,
    )
    if r.returncode != 0:
        one_line_error(r, "pip install")
        return
    check(psnr(image_of(sh.path("dm.png")), image_of(sh.path("photo.png"))) > 25, "poor")


@case("reconstruct-bilinear-borders", "bilinear keeps the recorded value at its own site")
def _(sh):
    from PIL import Image

    Image.fromarray(np.full((1, 1, 3), (217, 40, 90), np.uint8)).save(sh.path("one.png"))
    sh("splitcam reconstruct --method bilinear --pattern bayer --image one.png --out o.png")
    out = np.asarray(Image.open(sh.path("o.png")).convert("RGB"))
    check(out.shape == (1, 1, 3), f"shape {out.shape}")
    check(abs(int(out[0, 0, 0]) - 217) <= 1, f"R at the red site {out[0, 0, 0]}, recorded 217")


@case("reconstruct-keeps-input", "--out the raw file itself: refused, the raw kept")
def _(sh):
    photo(sh)
    sh("splitcam simulate photo.png --pattern D --sigma 0 --out raw.png")
    before = sh.path("raw.png").read_bytes()
    sh("splitcam reconstruct --model D --raw raw.png --sigma 0 --out raw.png", code=None)
    check(sh.path("raw.png").read_bytes() == before, "the raw image was replaced")


@case("reconstruct-tiled", "a network by tiles gives the whole image's reconstruction")
def _(sh):
    photo(sh, size=(201, 263))
    sh("splitcam simulate photo.png --pattern A --sigma 5 --out raw.png")
    sh("splitcam reconstruct --model A --raw raw.png --sigma 5 --precision fp32 --out a.png")
    sh(
        "splitcam reconstruct --model A --raw raw.png --sigma 5 --precision fp32 --tile 128 "
        "--out b.png"
    )
    diff = np.abs(image_of(sh.path("a.png")) - image_of(sh.path("b.png"))).max() * 255
    check(diff <= 1, f"tiles differ from the whole by {diff:.0f} levels")


@case("reconstruct-lmmse-borders", "the closed-form LMMSE of a router right at the border")
def _(sh):
    photo(sh)
    sh("splitcam simulate photo.png --pattern router-zou --sigma 0 --out raw.png")
    sh(
        "splitcam reconstruct --method lmmse --pattern router-zou --raw raw.png --sigma 0 "
        "--out lm.png"
    )
    err = ((image_of(sh.path("lm.png")) - image_of(sh.path("photo.png"))) ** 2).mean(axis=2)
    whole, inner = -10 * np.log10(err.mean()), -10 * np.log10(err[4:-4, 4:-4].mean())
    check(
        inner - whole < 1.0,
        f"the 4-pixel border costs {inner - whole:.1f} dB "
        f"(whole {whole:.2f}, interior {inner:.2f})",
    )


# --------------------------------------------------------------------------------- evaluate
EVAL = "--max-images 2 --crop 64 --sigmas 0 10 --quiet"


@case("evaluate-side-by-side", "a network against its LMMSE, one table")
def _(sh):
    sh(f"splitcam evaluate --model D --method lmmse --patterns D {EVAL} --out r")
    per = (
        json.loads((sh.path("r") / "results.json").read_text())
        if (sh.path("r") / "results.json").exists()
        else None
    )
    rows = table_rows(sh.path("r") / "table.md")
    check(any(" D " in r or "| D" in r for r in rows), "no row for D")
    check(per is None or per, "empty results")


@case("evaluate-adds-results", "a second evaluation into one folder keeps the first's rows")
def _(sh):
    sh(f"splitcam evaluate --method lmmse --patterns D {EVAL} --out r")
    sh(f"splitcam evaluate --method malvar2004 {EVAL} --out r")
    text = (sh.path("r") / "table.md").read_text()
    check("lmmse-D" in text and "malvar2004" in text, "a method's rows are missing")


@case("evaluate-datasets", "the paper's test sets by name (SPLITCAM_DATA)")
def _(sh):
    if "SPLITCAM_DATA" not in sh.env:
        raise Wrong("no SPLITCAM_DATA")
    sh(
        "splitcam evaluate --method lmmse --patterns bayer --datasets kodak24,mcmaster "
        "--max-images 1 --sigmas 0 --quiet --out r"
    )
    text = (sh.path("r") / "table.md").read_text()
    check("kodak24" in text.lower() and "mcmaster" in text.lower(), "a dataset is missing")


@case("evaluate-photon", "a photon-trained network in linear light")
def _(sh):
    sh(
        "splitcam evaluate --model D-photon --domain linear --photons 10 1000 --read-noise 2 "
        "--max-images 1 --crop 64 --quiet --out r"
    )
    check("D-photon" in (sh.path("r") / "table.md").read_text(), "no row")


@case("evaluate-flips", "averaged over the flips A's sensor is symmetric under")
def _(sh):
    sh("splitcam evaluate --model A --flips --max-images 1 --crop 64 --sigmas 0 --quiet --out r")


@case("evaluate-gaussian-net-on-photons", "a Gaussian-trained network on photon noise is said")
def _(sh):
    r = sh(
        "splitcam evaluate --model D --domain linear --photons 100 --max-images 1 --crop 64 "
        "--quiet --out r",
        code=None,
    )
    text = (r.stdout + r.stderr).lower()
    check("gaussian" in text or r.returncode != 0, "silently evaluated on other noise")


@case("evaluate-unknown-pattern", "an unknown pattern: one line, nothing written")
def _(sh):
    r = sh(f"splitcam evaluate --method lmmse --patterns nosuch {EVAL} --out r", code=1)
    one_line_error(r, "nosuch")
    check(not sh.path("r").exists(), "a folder was written")


@case("evaluate-bad-sigma", "a negative sigma refused")
def _(sh):
    r = sh("splitcam evaluate --method lmmse --patterns D --sigmas -5 --out r", code=None)
    check(r.returncode != 0, "exit 0")


@case("evaluate-user-patterns-labelled", "two user patterns in one evaluation keep their names")
def _(sh):
    sh("splitcam patterns export B --out b-mine.toml")
    sh("splitcam patterns export C --out c-mine.toml")
    sh(f"splitcam evaluate --method lmmse --patterns b-mine.toml,c-mine.toml {EVAL} --out r")
    text = (sh.path("r") / "table.md").read_text()
    check(text.count("lmmse-") >= 2, "the two patterns are not told apart")


@case("evaluate-whole-odd", "whole photos (one with odd sides), the paper's protocol")
def _(sh):
    sh(
        "splitcam evaluate --model bayer --method lmmse --patterns bayer --max-size 0 "
        "--sigmas 0 --quiet --out r",
        timeout=1200,
    )
    check(len(table_rows(sh.path("r") / "table.md")) > 3, "no rows")


@case("report", "an evaluation beside the paper's numbers")
def _(sh):
    sh(f"splitcam evaluate --model D --method lmmse --patterns D {EVAL} --out r")
    sh("splitcam report r --out rep")
    check(any(sh.path("rep").iterdir()), "empty report")


# ------------------------------------------------------------------------------------ train
def data_dir(sh) -> str:
    if "SPLITCAM_DATA" not in sh.env:
        raise Wrong("no SPLITCAM_DATA")
    return str(Path(sh.env["SPLITCAM_DATA"]) / "train")


TRAIN = "--batch-size 4 --patch-size 32 --max-images 16 --val-images 2 --val-crop 64 --quiet"


@case("train-resume", "train, stop, resume: the run continues to its step")
def _(sh):
    d = data_dir(sh)
    sh(f"splitcam train --pattern D --data {d} --steps 20 --checkpoint-every 10 {TRAIN} --out r")
    sh("splitcam train --out r --resume --steps 40 --quiet")
    from safetensors import safe_open

    with safe_open(str(sh.path("r") / "checkpoint.safetensors"), "np") as f:
        meta = f.metadata() or {}
    check("40" in json.dumps(meta), f"the checkpoint is not at step 40: {str(meta)[:200]}")


@case("train-divergence-keeps-state", "a diverged resume keeps the last good resumable state")
def _(sh):
    d = data_dir(sh)
    sh(f"splitcam train --pattern D --data {d} --steps 20 --checkpoint-every 10 {TRAIN} --out r")
    before = (sh.path("r") / "checkpoint.safetensors").read_bytes()
    r = sh("splitcam train --out r --resume --steps 200 --lr 1000 --quiet", code=None)
    check(r.returncode != 0, "a diverged run exited 0")
    check(
        "kept" in (r.stdout + r.stderr).lower() or "keep" in (r.stdout + r.stderr).lower(),
        "the failure does not say which state is kept",
    )
    check(
        (sh.path("r") / "checkpoint.safetensors").read_bytes() == before,
        "the resumable checkpoint was replaced by the diverged one",
    )
    sh("splitcam train --out r --resume --steps 30 --lr 0.001 --quiet")


@case("train-user-pattern-from-universal", "a user's pattern fine-tuned from `universal`")
def _(sh):
    d = data_dir(sh)
    sh("splitcam patterns export E --out mine.toml")
    sh(
        f"splitcam train --pattern mine.toml --init-from universal --data {d} --steps 10 {TRAIN} "
        "--out r"
    )
    sh("splitcam models export r --name mine")


@case("train-photon", "a network for photons in linear light")
def _(sh):
    d = data_dir(sh)
    sh(
        f"splitcam train --pattern D --noise photon --photons 10 10000 --read-noise 2 "
        f"--domain linear --data {d} --steps 10 {TRAIN} --out r"
    )


@case("train-plot", "the curves of a run")
def _(sh):
    d = data_dir(sh)
    sh(f"splitcam train --pattern D --data {d} --steps 10 --val-every 5 {TRAIN} --out r")
    sh("splitcam plot r --out curves.png")
    check(sh.path("curves.png").exists() or any(sh.path("r").glob("*.png")), "no chart")


@case("train-evaluate-run-folder", "a run folder in evaluate means its best network, said")
def _(sh):
    d = data_dir(sh)
    sh(f"splitcam train --pattern D --data {d} --steps 10 --val-every 5 {TRAIN} --out r")
    out = sh(f"splitcam evaluate --checkpoint r {EVAL.replace('--quiet', '')} --out e")
    check("best" in (out.stdout + out.stderr).lower(), "which network is not said")


@case("train-export-evaluate", "a run exported as a model, evaluated by its file")
def _(sh):
    d = data_dir(sh)
    sh(f"splitcam train --pattern B --data {d} --steps 10 --val-every 5 {TRAIN} --out r")
    sh("splitcam models export r --name mine")
    sh(f"splitcam evaluate --model models/mine.json {EVAL} --out e")
    check("mine" in (sh.path("e") / "table.md").read_text(), "no row for the exported model")
    r = sh("splitcam models export r --name mine", code=1)
    one_line_error(r, "--force")


@case("train-resume-nothing", "--resume where no run is: one line")
def _(sh):
    r = sh("splitcam train --out nothing --resume", code=1)
    one_line_error(r, "nothing")


@case("train-bad-data", "a missing data folder: one line")
def _(sh):
    r = sh("splitcam train --pattern D --data nowhere --steps 10 --out r", code=1)
    one_line_error(r, "nowhere")


@case("train-bad-steps", "zero steps refused")
def _(sh):
    r = sh("splitcam train --pattern D --data nowhere --steps 0 --out r", code=None)
    check(r.returncode != 0, "exit 0")


@case("train-config", "an experiment file of the repository, shortened")
def _(sh):
    d = data_dir(sh)
    sh(
        f"splitcam train --config {sh.clone}/experiments/D.toml --data {d} --steps 4 {TRAIN} "
        "--out r"
    )


# ----------------------------------------------------------------------------------- models
@case("models-list", "the shipped models with their budgets")
def _(sh):
    out = sh("splitcam models").stdout
    for name in ("universal", "bayer", "D-opt"):
        check(f"| {name} " in out, f"{name} missing")


# ----------------------------------------------------------------------------------- design
@case("design-lmmse", "a pattern designed for the closed-form LMMSE")
def _(sh):
    sh("splitcam design --pattern D --steps 20 --out designed.toml --quiet")
    sh("splitcam patterns show designed.toml --out designed.png")


@case("design-search", "a search of the design settings, or the extra's install command")
def _(sh):
    r = sh(
        "splitcam design --pattern D --search 2 --steps 5 --study st --out best.toml --quiet",
        code=None,
    )
    if r.returncode != 0:
        one_line_error(r, "pip install")
    else:
        check(sh.path("best.toml").exists(), "no pattern written")


@case("optics-lens", "kernels of a metasurface lens")
def _(sh):
    sh("splitcam optics --profile lens --distance 2 --out lenses.toml")
    sh("splitcam patterns show lenses.toml --out lenses.png")


@case("optics-rcwa", "a published router's spectra, named after the design")
def _(sh):
    design = sh.clone / "experiments/fullwave/designs/zou2022-16x16.csv"
    sh(f"splitcam optics rcwa {design} --order 2 --wavelengths 450,550,650 --quiet --out z")
    photo(sh)
    sh("splitcam simulate photo.png --pattern z/zou2022-16x16.toml --sigma 0 --out raw.png")
    sh(
        "splitcam reconstruct --method lmmse --pattern z/zou2022-16x16.toml --raw raw.png "
        "--sigma 0 --out rec.png"
    )
    truth = image_of(sh.path("photo.png"))
    flat = psnr(np.broadcast_to(truth.mean(axis=(0, 1)), truth.shape), truth)
    rec = psnr(image_of(sh.path("rec.png")), truth)
    check(rec > flat + 3, f"LMMSE {rec:.2f} dB, the photo's mean colour alone {flat:.2f} dB")


@case("optics-rcwa-resume", "the same solve run again takes its solves from the log")
def _(sh):
    design = sh.clone / "experiments/fullwave/designs/zou2022-16x16.csv"
    cmd = f"splitcam optics rcwa {design} --order 1 --wavelengths 450,650 --quiet --out z"
    sh(cmd)
    out = sh(cmd).stdout
    check("2 of 2 solves taken from" in out, "solved again")


@case("optics-rcwa-bad-angles", "f/0 and a grazing chief ray refused, nothing written")
def _(sh):
    design = sh.clone / "experiments/fullwave/designs/zou2022-16x16.csv"
    for extra in ("--f-number 0", "--f-number 2 --chief-ray 80"):
        r = sh(f"splitcam optics rcwa {design} {extra} --out z", code=1)
        one_line_error(r)
        check(not sh.path("z").exists(), f"{extra}: a folder was written")


# ------------------------------------------------------------------------------------ study
@case("study-exposure", "filters against routers at equal light, with its table")
def _(sh):
    sh("splitcam study exposure --max-images 1 --crop 64 --points 3 --quiet --out s")
    check(any(sh.path("s").glob("*.md")), "no table")


@case("study-breakeven", "where a router ties the RGBW array")
def _(sh):
    sh(
        "splitcam study breakeven --max-images 1 --crop 64 --points 3 --eta 0.5 0.9 --chi 0 0.3 "
        "--quiet --out b"
    )
    check(any(sh.path("b").glob("*.md")), "no table")


# ------------------------------------------------------------------------------------- data
@case("data-list", "which datasets are here")
def _(sh):
    out = sh("splitcam data list").stdout.lower()
    check("kodak24" in out and "mcmaster" in out, "datasets missing")


@case("data-download-offline", "a download that cannot reach its server says so in one line")
def _(sh):
    sh.env["SPLITCAM_MIRROR"] = "http://127.0.0.1:9"
    r = sh("splitcam data download kodak24 --to d", code=None)
    check(r.returncode != 0, "exit 0 without data")
    one_line_error(r)


# --------------------------------------------------------------------------------- reproduce
@case("reproduce-small", "the paper's tables from the shipped models, on one image")
def _(sh):
    if "SPLITCAM_DATA" not in sh.env:
        raise Wrong("no SPLITCAM_DATA")
    sh(
        "splitcam reproduce --max-images 1 --sigmas 0 --no-baselines --quiet --out rep",
        timeout=1200,
    )
    check(any(sh.path("rep").glob("*.md")), "no tables")


# ---------------------------------------------------------------------------------- examples
@case("example-compare-patterns", "examples/01")
def _(sh):
    sh(f"python {sh.clone}/examples/01_compare_patterns.py")


@case("example-own-pattern", "examples/02")
def _(sh):
    sh(f"python {sh.clone}/examples/02_your_own_pattern.py")


@case("example-deepinv", "examples/07: runs, or exits 1 with the command that fixes it")
def _(sh):
    r = sh(f"python {sh.clone}/examples/07_deepinv_solver.py", code=None)
    if r.returncode != 0:
        one_line_error(r, "pip install")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs/results/battery")
    parser.add_argument("--work", type=Path, default=Path("/tmp/splitcam-battery"))
    parser.add_argument("--only", nargs="+")
    args = parser.parse_args()
    data = os.environ.get("SPLITCAM_DATA")
    if args.work.exists():
        shutil.rmtree(args.work)
    clone = args.work / "clone"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    commit = subprocess.run(
        ["git", "-C", str(clone), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    sys.path.insert(0, str(clone / "src"))
    results = []
    for name, what, fn in CASES:
        if args.only and name not in args.only:
            continue
        folder = args.work / name
        folder.mkdir(parents=True)
        sh = Shell(clone, folder, data)
        start = time.perf_counter()
        try:
            fn(sh)
            verdict, detail = "ok", ""
        except Tracebacks as exc:
            verdict, detail = "traceback", str(exc)
        except Wrong as exc:
            verdict, detail = "wrong", str(exc)
        except subprocess.TimeoutExpired as exc:
            verdict, detail = "wrong", f"timed out: {exc.cmd}"
        except Exception:  # a fault of the battery itself
            verdict, detail = "battery error", traceback.format_exc().strip().splitlines()[-1]
        seconds = time.perf_counter() - start
        results.append(
            {
                "case": name,
                "what": what,
                "commands": sh.log,
                "verdict": verdict,
                "detail": detail,
                "seconds": round(seconds, 1),
            }
        )
        print(f"{verdict:9s} {name} ({seconds:.0f} s) {detail}", flush=True)
    counts = {
        v: sum(r["verdict"] == v for r in results)
        for v in ("ok", "wrong", "traceback", "battery error")
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "battery.json").write_text(
        json.dumps({"commit": commit, "counts": counts, "cases": results}, indent=1) + "\n"
    )
    lines = [
        "# A new user's battery",
        "",
        f"{len(results)} cases on a fresh clone (commit {commit}): "
        + ", ".join(f"{n} {v}" for v, n in counts.items())
        + ".",
        "",
        "```bash",
        "SPLITCAM_DATA=DIR python studies/battery/battery.py",
        "```",
        "",
        "| case | what a user does | commands | verdict | seconds | detail |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        cmds = "<br>".join(f"`{c}`" for c in r["commands"])
        lines.append(
            f"| {r['case']} | {r['what']} | {cmds} | {r['verdict']} | "
            f"{r['seconds']:.0f} | {r['detail'].replace('|', '/')} |"
        )
    (args.out / "README.md").write_text("\n".join(lines) + "\n")
    print(counts)


if __name__ == "__main__":
    main()
