#!/usr/bin/env bash
# The exposure answer (docs/results/exposure/README.md, "The answer, with its uncertainty"):
# every sensor behind silicon and the D5100's IR cut, routers under the cone of an f/2 lens,
# read noise 2 e-, full well 6000 e-, Kodak24 + McMaster + the last six training photos (held
# out of every training run) at 192 px, 13 exposures, against the D5100's RGBW and Bayer
# arrays. The one home of the answer's pattern list; resumable (the study keeps its rows in
# OUT/evaluation, so a pattern added later is scored alone).
#
#   SPLITCAM_DATA=DIR bash studies/exposure/answer.sh [STUDY OPTIONS...]
#
#   OUT=DIR             where (default docs/results/exposure/answer/rn2)
#   ADD=,P1,P2          patterns added to the list (names or files)
#   PATTERNS=P1,P2      another list instead (the illuminant studies use a short one)
#   STUDY OPTIONS       more `splitcam study exposure` options: --update (score again the rows of
#                       a network shipped since), --checkpoint RUN, --illuminant A, ...
set -euo pipefail
: "${SPLITCAM_DATA:?set SPLITCAM_DATA to the data folder}"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
HELD=/tmp/splitcam-heldout6
mkdir -p "$HELD"
for f in $(ls "$SPLITCAM_DATA"/train/*.jpg | tail -6); do ln -sf "$(realpath "$f")" "$HELD/"; done
K=docs/results/fullwave/kernels-793
A=docs/results/fullwave/angles/patterns
D=docs/results/fullwave/design
ALL=rgbw-d5100,bayer-d5100,router-zou-fullwave-f2,router-best-fullwave-f2
ALL=$ALL,$K/zou-f2-computed.json,$K/zou-f2-nearest.toml,$K/best-f2-computed.json,$K/best-f2-nearest.toml
ALL=$ALL,$A/zou-f2-centre-6wl.toml,$A/zou-f2-corner-6wl.toml,$A/best-f2-centre-6wl.toml
ALL=$ALL,$A/best-f2-corner-6wl.toml,$A/zou-f2-middle-6wl.toml,$A/best-f2-middle-6wl.toml
ALL=$ALL,$D/zou-n30-binary-lr0.03/verify/zou-n30-binary-f2-fmmax797.toml
ALL=$ALL,$D/best-n30-fab-f2/kernels-793/best-n30-fab-f2-computed.json
ALL=$ALL,$D/best-n30-fab-f2/kernels-793/best-n30-fab-f2-nearest.toml
ALL=$ALL,$D/best-n30-fab-f2/verify/best-n30-fab-f2-f2-fmmax797.toml
ALL=$ALL,$D/best-n300-fab-f2/verify/best-n300-fab-f2-f2-fmmax797.toml
ALL=$ALL,router-best-n30-fullwave-f2,router-best-n300-fullwave-f2
splitcam study exposure --datasets "kodak24,mcmaster,$HELD" --crop 192 \
    --patterns "${PATTERNS:-$ALL}${ADD:-}" \
    --photons 1 2.15 4.64 10 21.5 46.4 100 215 464 1000 2150 4640 10000 --read-noise 2 \
    --model universal-photon --reference rgbw-d5100,bayer-d5100 \
    --stack silicon,ir-cut --full-well 6000 --out "${OUT:-docs/results/exposure/answer/rn2}" "$@"
