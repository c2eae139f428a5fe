#!/usr/bin/env bash
# The colour stage and its cool-down for each shipped network named, one after another on one
# thread (docs/results/colour/README.md). A finished stage is skipped and an interrupted one
# resumes from its checkpoint, so the script can be run again after a stop.
#   SPLITCAM_DATA=DIR bash studies/colour/stages.sh D A B ...
set -euo pipefail
: "${SPLITCAM_DATA:?set SPLITCAM_DATA to the data folder (its train/ holds the photos)}"
export OMP_NUM_THREADS=1
# --resume where the folder holds a checkpoint: an interrupted stage continues, a finished one
# does no more steps.
again() { [ -f "$1/checkpoint.safetensors" ] && echo --resume || true; }
for name in "$@"; do
    out="runs/colour/$name-colour"
    splitcam train --config "experiments/colour/$name-colour.toml" --data "$SPLITCAM_DATA/train" \
        --out "$out" $(again "$out") --quiet
    out="runs/colour/$name-cooldown"
    splitcam train --config "experiments/colour/$name-cooldown.toml" \
        --init-from "runs/colour/$name-colour" --data "$SPLITCAM_DATA/train" \
        --out "$out" $(again "$out") --quiet
done
