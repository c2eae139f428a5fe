#!/usr/bin/env bash
# The measurements of docs/results/universal/README.md, from the repository root, after
# `splitcam sweep experiments/universal.toml experiments/universal-holdout.toml ...` and
# `splitcam models export runs/universal --name universal --ship`. Two processes at a time,
# one thread each (what the README's timings are).
set -euo pipefail
RESULTS=docs/results/universal
DATA=${DATA:-${SPLITCAM_DATA:?set SPLITCAM_DATA to the data root (splitcam data download train)}/train}
PAT=$RESULTS/patterns
export OMP_NUM_THREADS=1

# 1. Zero-shot on the library (held-out photos, whole) | 2. patterns it never saw, with the run
#    that left B and E out of its mix.
python $RESULTS/heldout.py universal --threads 1 --out $RESULTS/heldout.md &
python $RESULTS/heldout.py universal --threads 1 \
    --patterns B,E,rgbw,quad,router-zou,$PAT/random-router.toml,$PAT/random-scatter.toml \
    --extra "without B, E=${HOLDOUT:-$RESULTS/models/universal-holdout.json}" --out $RESULTS/unseen.md &
wait

# 3. Fine-tuning for 10 minutes (the default budget) on a library pattern and on one it never
#    saw; the curves are the runs' validation logs.
for pair in "D rgbw" "quad router-zou"; do
    for p in $pair; do
        splitcam train --pattern $p --init-from universal --data $DATA --threads 1 \
            --val-every 200 --out runs/ft-$p --quiet &
    done
    wait
done
python $RESULTS/heldout.py universal --threads 2 --patterns D,rgbw,quad,router-zou \
    --extra "fine-tuned 10 min=runs/ft-{pattern}" --out $RESULTS/fine-tuned.md

# 4. Design: closed form against the network in the loop, from D's support, both scored by
#    the universal network and the LMMSE on the held-out photos.
splitcam design --pattern D --out $RESULTS/D-closed-form.toml --quiet
splitcam design --pattern D --objective network --data $DATA --out $RESULTS/D-network.toml --quiet
python $RESULTS/heldout.py universal --threads 2 \
    --patterns D,$RESULTS/D-closed-form.toml,$RESULTS/D-network.toml --out $RESULTS/design.md

