#!/usr/bin/env bash
# Each second-stage probe blended back towards the shipped model it started from, weight by
# weight (splitcam models blend), and gated (docs/results/colour/README.md, "Half-way back to
# the shipped network"). The probes' candidates are made first ("The second-stage probes
# finished with their cool-downs": runs/colour/candidates/{bayer-quarter,bayer-quarter2,
# bayer-halfquarter,E-halfquarter}); the probe of bayer before its cool-down is exported here.
# Ships nothing: `splitcam models gate runs/colour/blend/soup3-0.5/bayer.json --ship` does.
#   SPLITCAM_DATA=DIR bash studies/colour/blends.sh
set -euo pipefail
: "${SPLITCAM_DATA:?set SPLITCAM_DATA to the data folder (its train/ holds the photos)}"
export OMP_NUM_THREADS=1
C=runs/colour/candidates B=runs/colour/blend
# The shipped models these blends start from, before the blend replaced bayer (the gate then
# scored against them: to repeat its numbers, run this at that commit, 36f4d54).
mkdir -p "$B/before"
for f in bayer.json bayer.safetensors E.json E.safetensors; do
    git show "36f4d54:src/splitcam/weights/models/$f" > "$B/before/$f"
done
blend() { splitcam models blend "$1" "$2" --weight "$3" --name "$4" --out "$5" --force "${@:6}"; }
splitcam models export runs/colour/probe/bayer-quarter/checkpoint.safetensors --name bayer \
    --out "$B/quarter-raw" --force
blend "$B/before/bayer.json" "$B/quarter-raw/bayer.json" 0.25 bayer "$B/raw-25"
blend "$B/before/bayer.json" "$B/quarter-raw/bayer.json" 0.5 bayer "$B/raw-50"
for c in bayer-quarter bayer-quarter2 bayer-halfquarter; do blend "$B/before/bayer.json" "$C/$c/bayer.json" 0.5 bayer "$B/$c-50"; done
blend "$B/before/E.json" "$C/E-halfquarter/E.json" 0.5 E "$B/E-halfquarter-50"
# E's control, its second stage at half size alone (stages.sh E-half), and its blends.
[ -f "$C/E-half/E.json" ] || splitcam models export runs/colour/E-half-cooldown/checkpoint.safetensors \
    --name E --out "$C/E-half"
blend "$B/before/E.json" "$C/E-half/E.json" 0.5 E "$B/E-half-50"
blend "$C/E-halfquarter/E.json" "$C/E-half/E.json" 0.5 E "$B/Esoup"
blend "$B/before/E.json" "$B/Esoup/E.json" 0.5 E "$B/Esoup-0.5"
# The three cooled-down bayer probes averaged (a uniform soup), then half-way back.
blend "$C/bayer-quarter/bayer.json" "$C/bayer-quarter2/bayer.json" 0.5 bayer "$B/soup2" --storage float32
blend "$B/soup2/bayer.json" "$C/bayer-halfquarter/bayer.json" 0.3333333 bayer "$B/soup3"
# (the shipped soup3-0.5 was written with --description, the one line its header holds)
for w in 0.5 0.75; do blend "$B/before/bayer.json" "$B/soup3/bayer.json" "$w" bayer "$B/soup3-$w"; done
splitcam models gate "$B"/{raw-25,raw-50,bayer-quarter-50,bayer-quarter2-50,bayer-halfquarter-50}/bayer.json \
    "$B"/{soup3,soup3-0.5,soup3-0.75}/bayer.json "$B/E-halfquarter-50/E.json" \
    --data "$SPLITCAM_DATA/train" --threads 1 --table "$B/gate.md"
splitcam models gate "$C/E-half/E.json" "$B"/{E-half-50,Esoup,Esoup-0.5}/E.json \
    --data "$SPLITCAM_DATA/train" --threads 1 --table "$B/gate-E.md"
splitcam evaluate --model "$C/E-half/E.json" --datasets kodak24,mcmaster --sigmas 0 15 --precision fp32 \
    --out runs/colour/describe-E-half --quiet
for m in soup3-0.5/bayer bayer-quarter-50/bayer; do
    splitcam evaluate --model "$B/$m.json" --datasets kodak24,mcmaster --sigmas 0 15 --precision fp32 \
        --out "$B/describe-${m%%/*}" --quiet
done
# A fourth probe (the quarter-size one again, seed 2, from the bayer before the blend) averaged
# in; gated against the blend shipped from the three (run after it shipped).
if [ ! -f "$C/bayer-quarter-s2/bayer.json" ]; then
    splitcam train --config experiments/colour/bayer-quarter.toml --init-from "$B/before/bayer.json" \
        --seed 2 --data "$SPLITCAM_DATA/train" --out runs/colour/probe/bayer-quarter-s2 --quiet
    splitcam train --config experiments/colour/bayer-half2-cooldown.toml --seed 2 \
        --init-from runs/colour/probe/bayer-quarter-s2 --data "$SPLITCAM_DATA/train" \
        --out runs/colour/probe/bayer-quarter-s2-cooldown --quiet
    splitcam models export runs/colour/probe/bayer-quarter-s2-cooldown/checkpoint.safetensors \
        --name bayer --out "$C/bayer-quarter-s2"
fi
blend "$B/soup3/bayer.json" "$C/bayer-quarter-s2/bayer.json" 0.25 bayer "$B/soup4"
blend "$B/before/bayer.json" "$B/soup4/bayer.json" 0.5 bayer "$B/soup4-0.5"
blend "$B/before/bayer.json" "$C/bayer-quarter-s2/bayer.json" 0.5 bayer "$B/bayer-quarter-s2-50"
splitcam models gate "$C/bayer-quarter-s2/bayer.json" "$B"/{bayer-quarter-s2-50,soup4,soup4-0.5,before}/bayer.json \
    --data "$SPLITCAM_DATA/train" --threads 1 --table "$B/gate-soup4.md"
splitcam evaluate --model "$B/soup4-0.5/bayer.json" --datasets kodak24,mcmaster --sigmas 0 15 \
    --precision fp32 --out "$B/describe-soup4-0.5" --quiet

# Every shipped network half-way back to the model before its last stage (the commit that
# shipped that model), gated; A described on the test sets.
P="$B/prev"
for spec in A:28ad82a B:30dce49 C:2c3f297 D:fd381d1 E:11a2f4f D-photon:312506d A-photon:1ba829a \
    bayer-photon:d883ced router-zou-photon:f8d6b3c router-best-photon:42c9ddc universal-photon:c0747de; do
    m=${spec%%:*} commit=${spec#*:}
    mkdir -p "$P/$m"
    for f in json safetensors; do git show "$commit:src/splitcam/weights/models/$m.$f" > "$P/$m/$m.$f"; done
    blend "$P/$m/$m.json" "$m" 0.5 "$m" "$P/half-$m"
done
splitcam models gate "$P"/half-{A/A,B/B,C/C,D/D,E/E}.json --data "$SPLITCAM_DATA/train" --threads 1 \
    --table "$P/gate-srgb.md"
splitcam models gate "$P"/half-{D-photon/D-photon,A-photon/A-photon,bayer-photon/bayer-photon}.json \
    "$P"/half-{router-zou-photon/router-zou-photon,router-best-photon/router-best-photon}.json \
    "$P/half-universal-photon/universal-photon.json" --data "$SPLITCAM_DATA/train" --threads 1 \
    --table "$P/gate-photon.md"
splitcam evaluate --model "$P/half-A/A.json" --datasets kodak24,mcmaster --sigmas 0 15 --precision fp32 \
    --out "$P/describe-half-A" --quiet
