#!/usr/bin/env bash
# The whole calibration loop on the simulator, as `make demo` runs it:
# excite -> fit planes -> fit hysteresis -> validate (which effect is missing?) -> refit -> validate -> report.
set -euo pipefail
export PATH="$PWD/.venv/bin:$PATH"  # the commands validate prints call `endocal` by name
E=endocal
# OUT: `make demo` gives demo-out; run by hand without it, outside the repository (printed)
OUT=${1:-${TMPDIR:-/tmp}/endocal-demo}
mkdir -p "$OUT"
echo "writing the demo's runs, models and report into $OUT"
step() { local t0=$SECONDS; printf '\n\033[1m== %s\033[0m\n$' "$1"; printf ' %q' "${@:2}"; printf '\n'; "${@:2}"; printf '(%d s)\n' $((SECONDS - t0)); }

step "bending planes: single-knob sweeps of the four half-planes" \
  $E excite planes --out "$OUT/planes" --seed 1 --force --quiet
step "fit the deviation angles and the orthogonal compensator" \
  $E fit planes "$OUT/planes" --out "$OUT/planes.json" --force
step "sweep again through the compensator (knob commands only) and measure what is left: the paper's figure 8" \
  $E excite planes --planes "$OUT/planes.json" --out "$OUT/planes-after" --seed 6 --force --quiet
$E fit planes "$OUT/planes" --after "$OUT/planes-after" --out "$OUT/planes.json" --force
step "estimation runs: the duodenoscope paper's damped sine, and a chirp (several speeds tell a delay from speed-dependent friction)" \
  $E excite damped-sine --amplitude 85 --out "$OUT/train" --seed 2 --force --quiet
$E excite chirp --amplitude 50 --out "$OUT/chirp" --seed 4 --force --quiet
step "validation runs, used by no fit: band-limited random input and the paper's triangle" \
  $E excite random --amplitude 60 --out "$OUT/test" --seed 3 --force --quiet
$E excite triangle --amplitude 50 --out "$OUT/check" --seed 5 --force --quiet
step "fit the paper's modified Prandtl-Ishlinskii model on the estimation runs" \
  $E fit hysteresis "$OUT/train" "$OUT/chirp" --axis ap --model pi --effects envelope --out "$OUT/pi-envelope.json" --force
# The loop: validate holds the model against the validation runs, refits every candidate effect
# on the estimation runs the model file names, names the most likely missing effect and prints
# the command that adds it; run that command, validate again (it shows the error falling),
# until nothing significant is missing or three effects have been added.
model="$OUT/pi-envelope.json"
models=("$model")
for round in 1 2 3 4; do
  step "round $round: hold $(basename "$model") against the validation runs: how far off, where, which effect is missing" \
    $E validate "$model" "$OUT/test" "$OUT/check" --json-out "$OUT/validate-$(basename "$model")"
  refit=$(python -c "import json,sys; s=json.load(open(sys.argv[1]))['suspects']; print(s[0]['command'] if s else '')" "$OUT/validate-$(basename "$model")")
  if [ -z "$refit" ]; then
    echo "validate finds nothing significant missing: the loop ends"
    break
  fi
  [ "$round" = 4 ] && break
  # the printed command is shell-quoted (a folder with a space stays one argument): split it as a shell would
  mapfile -d '' -t argv < <(python -c "import shlex,sys; sys.stdout.write(''.join(a + '\0' for a in shlex.split(sys.argv[1])))" "$refit")
  model=$(python -c "import sys; a=sys.argv[1:]; print(a[a.index('--out') + 1])" "${argv[@]}")
  step "add the suspected effect: the exact command validate printed" "${argv[@]}" --force
  models+=("$model")
done
step "what these records cannot show (the other knob never moved, the sheath's wrap never changed): the protocol that would, for excite to record" \
  $E validate "$model" "$OUT/test" "$OUT/check" --next "$OUT/next.toml"
step "feedforward compensation on the simulator (desired vs reached angle)" \
  $E validate "$model" --protocol triangle --set amplitude_deg=40 --runs-out "$OUT/playback"
step "report" \
  $E report "${models[@]}" --data "$OUT/check" --data "$OUT/test" --planes "$OUT/planes.json" --out "$OUT/report.html" --force
printf '\nResults are in %s/: runs (run.json, motor/, tracker/, truth/, aligned.parquet), planes.json, model files, next.toml, report.html\n' "$OUT"
