#!/usr/bin/env bash
# A cone design (docs/results/fullwave/README.md, "The cone in the loss") verified once its run
# ends, in three resumable stages (each keeps its solves; run the same line again after a
# stop). One thread each; run two designs' stages side by side on the two cores.
#
#   bash studies/fullwave/verify_cone.sh solve best-n30-f2     # the binary design at 797 terms,
#       # f/2 cone, six wavelengths, against the leaderboard design at the same setting (one
#       # layer or layers stacked); WORKERS=2 shares its solves between two processes
#   bash studies/fullwave/verify_cone.sh kernels best-n30-f2   # its kernels from the fields
#       # (793 terms, 410-690 nm, f/2; about two hours of one thread), in the design's folder;
#       # PARTS=2 shares the solving between two processes, one core each
#   SPLITCAM_DATA=DIR bash studies/fullwave/verify_cone.sh answer best-n30-f2 best-n300-f2
#       # the exposure answer (studies/exposure/answer.sh) with the designs added (only the new
#       # patterns are scored): the solve's pattern, and the kernels' where that stage has run
set -euo pipefail
export OMP_NUM_THREADS=1
D=docs/results/fullwave/design
K=docs/results/fullwave/kernels-793
A=docs/results/fullwave/angles/patterns
LAMS=433,467,533,567,633,667
stage=$1
shift
case "$stage" in
solve)
    for name in "$@"; do
        # one layer (NAME.csv) or layers stacked (NAME-layer1.csv, NAME-layer2.csv, ...)
        layers=("$D/$name/$name.csv")
        [ -f "${layers[0]}" ] || layers=("$D/$name/$name"-layer[0-9].csv)
        [ -f "${layers[0]}" ] || { echo "$D/$name: the run has not ended" >&2; exit 1; }
        # the run's own layer thicknesses, spacer depth and spacer between layers (its state)
        read -r thickness depth spacer < <(python -c 'import json, sys
s = json.load(open(sys.argv[1]))["settings"]
t = s["stack"][1]
print(",".join(map(str, t if isinstance(t, list) else [t])), s["stack"][2], s.get("spacer", 0))' \
            "$D/$name/state.json")
        splitcam optics rcwa "${layers[@]}" --thickness ${thickness//,/ } --depth "$depth" \
            --spacer "$spacer" --solver fmmax-jones --terms 797 --wavelengths $LAMS --f-number 2 \
            --threads 1 --workers "${WORKERS:-1}" --name "$name-f2-fmmax797" \
            --out "$D/$name/verify" --quiet
        verify=(python studies/fullwave/verify_design.py
            "$D/$name/verify/$name-f2-fmmax797-spectra.csv" "$A/best-f2-centre-6wl.toml")
        { echo "# $name solved again: 797 terms, f/2 cone, against the leaderboard design"
          echo; echo "The bare pixel:"; echo
          "${verify[@]}"
          echo; "${verify[@]}" --stack silicon,ir-cut; } | tee "$D/$name/verify/verify.md"
    done
    ;;
kernels)
    for name in "$@"; do
        # files named as the published routers' (KEY-f2-computed.json): the key without -f2
        kernels=(python studies/fullwave/kernels.py --designs "${name%-f2}=$D/$name/$name.csv"
            --terms 793 --out "$D/$name/kernels-793")
        parts=${PARTS:-1}
        if [ "$parts" -gt 1 ]; then
            for k in $(seq 1 "$parts"); do "${kernels[@]}" --part "$k/$parts" & done
            wait
        fi
        "${kernels[@]}"
    done
    ;;
answer)
    : "${SPLITCAM_DATA:?set SPLITCAM_DATA to the data folder}"
    added=""
    for name in "$@"; do
        # the kernels where that stage has run (the solve's pattern alone otherwise)
        for f in "$D/$name/kernels-793/${name%-f2}-f2-computed.json" \
            "$D/$name/kernels-793/${name%-f2}-f2-nearest.toml"; do
            if [ -f "$f" ]; then added="$added,$f"; fi
        done
        added="$added,$D/$name/verify/$name-f2-fmmax797.toml"
    done
    ADD="$added" bash studies/exposure/answer.sh --quiet
    ;;
*)
    echo "usage: verify_cone.sh solve|kernels|answer NAME..." >&2
    exit 2
    ;;
esac
