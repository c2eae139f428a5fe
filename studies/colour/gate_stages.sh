#!/usr/bin/env bash
# Gate the colour stage of each shipped network named (after studies/colour/stages.sh): export
# its cool-down as a candidate, score it against the shipped model by the gate every model
# passes (splitcam models gate: held-out photos at half size, at the model's validation
# levels), and describe both on the colourful held-out photos and the skimage photos (they
# choose nothing).
# Ships nothing: `splitcam models gate runs/colour/candidates/NAME/MODEL.json --ship` does.
# A stage named other than its model (an arm such as D-b32long) is given as STAGE:MODEL.
#   SPLITCAM_DATA=DIR bash studies/colour/gate_stages.sh D A D-b32long:D ...
set -euo pipefail
: "${SPLITCAM_DATA:?set SPLITCAM_DATA to the data folder (its train/ holds the photos)}"
export OMP_NUM_THREADS=1
mkdir -p runs/colour/candidates runs/colour/gates
[ -d runs/colour/heldout/colourful ] || python studies/colour/heldout.py --data "$SPLITCAM_DATA/train"
for spec in "$@"; do
    name="${spec%%:*}"   # the stage (its runs and tables)
    model="${spec#*:}"   # the shipped model it continues (the stage's name when not given)
    candidate="runs/colour/candidates/$name/$model.json"
    [ -f "$candidate" ] || splitcam models export "runs/colour/$name-cooldown/checkpoint.safetensors" \
        --name "$model" --out "runs/colour/candidates/$name"
    splitcam models gate "$candidate" --data "$SPLITCAM_DATA/train" --threads 1 \
        --table "runs/colour/gates/$name.md"
    out="runs/colour/describe-$name"
    run="runs/colour/$name-cooldown/checkpoint.safetensors"
    # The photon networks at their validation exposures in linear light, the others at σ 0 / 15.
    levels=(--sigmas 0 15)
    case "$model" in *-photon) levels=(--photons 30 300 --domain linear) ;; esac
    splitcam evaluate --model "$model" --checkpoint "$run" --datasets runs/colour/heldout/colourful \
        "${levels[@]}" --precision fp32 --out "$out-colourful" --quiet
    splitcam evaluate --model "$model" --checkpoint "$run" --datasets default --max-size 0 \
        "${levels[@]}" --precision fp32 --out "$out-skimage" --quiet
done
