#!/usr/bin/env bash
# Regularizer ablation on a toycars scene (issue 6: choose k and λ by measurement).
#
#   scripts/ablation.sh OUT_DIR
#
# Generates the scene (once), builds ground-truth object-ID maps, trains the baseline once,
# then runs `semdynreg compare` for every (k, λ) below against that same baseline (same seed
# and schedule), and prints a Markdown table of the moving-object crop PSNR/SSIM/LPIPS (mean
# over t = 0…5 s), the static objects' crop PSNR and the deformation-consistency RMS.
# Settings (environment): BIN (default target/release/semdynreg; build it first with
# `cargo build --release`), PRESET (scene1), DRIVE (1.0: the fraction of its route the moving
# vehicle covers, `synth toycars --drive`), W×H (160×120), FRAMES (96), ITERS (3000),
# SEED (0), POINTS (20000 random initial Gaussians, as `semdynreg demo`), KS ("1 3 8" at λ = LAMBDA_AT_K), LAMBDAS ("0.01 0.1 1" at k = K_AT_LAMBDA),
# MEMBERSHIP (view: the paper's per-view groups; persistent: `[reg] membership`, run names
# get a `_persistent` suffix; several invocations into one OUT_DIR share the baseline),
# EXTRA (TOML appended to every run's config, baseline included, e.g.
# EXTRA=$'[field]\ndeform_scale = false'; use a fresh OUT_DIR when you change it).
# Needs jq for the table. Runs that already finished are reused, so it can be resumed.
set -euo pipefail

OUT=${1:?usage: scripts/ablation.sh OUT_DIR}
BIN=${BIN:-target/release/semdynreg}
PRESET=${PRESET:-scene1}
DRIVE=${DRIVE:-1.0}
W=${W:-160}
H=${H:-120}
FRAMES=${FRAMES:-96}
ITERS=${ITERS:-3000}
SEED=${SEED:-0}
POINTS=${POINTS:-20000}
KS=${KS-"1 3 8"}
LAMBDA_AT_K=${LAMBDA_AT_K:-0.1}
LAMBDAS=${LAMBDAS-"0.01 0.1 1"}
K_AT_LAMBDA=${K_AT_LAMBDA:-3}
MEMBERSHIP=${MEMBERSHIP:-view}
case $MEMBERSHIP in
  view) SUFFIX="" ;;
  persistent) SUFFIX="_persistent" ;;
  *) echo "MEMBERSHIP must be view or persistent, got $MEMBERSHIP" >&2; exit 1 ;;
esac
DICT="white SUV,yellow sedan,green SUV"

[ -x "$BIN" ] || { echo "no executable at $BIN (cargo build --release, or set BIN)" >&2; exit 1; }
command -v jq >/dev/null || { echo "jq is needed for the summary table" >&2; exit 1; }
mkdir -p "$OUT"
SCENE="$OUT/scene"
if [ ! -f "$SCENE/objects.json" ]; then
  "$BIN" synth toycars --out "$SCENE" --preset "$PRESET" --width "$W" --height "$H" \
    --frames "$FRAMES" --seed "$SEED" --drive "$DRIVE"
fi
"$BIN" segment "$SCENE" --dict "$DICT" --masks gt --labels gt

# One shared baseline: every configuration's compare folder links `baseline` to it; the first
# compare trains it, the others find it finished and reuse it. The same for compare's
# rigid-objects run: it trains without the regularizer, so no [reg] setting changes it.
BASE="$OUT/baseline"
RIGID="$OUT/rigid"
mkdir -p "$BASE" "$RIGID"

run_config() { # name k lambda
  local dir="$OUT/$1"
  mkdir -p "$dir"
  [ -e "$dir/baseline" ] || ln -s "$(realpath "$BASE")" "$dir/baseline"
  [ -e "$dir/rigid" ] || ln -s "$(realpath "$RIGID")" "$dir/rigid"
  printf '[init]\nrandom_points = %s\n[reg]\nk = %s\nlambda = %s\nmembership = "%s"\n' \
    "$POINTS" "$2" "$3" "$MEMBERSHIP" >"$dir/config.toml"
  [ -z "${EXTRA:-}" ] || printf '%s\n' "$EXTRA" >>"$dir/config.toml"
  [ -f "$dir/results.json" ] ||
    "$BIN" compare "$SCENE" --out "$dir" --iters "$ITERS" --seed "$SEED" --config "$dir/config.toml"
}

CONFIGS=()
for k in $KS; do CONFIGS+=("k${k}_l${LAMBDA_AT_K}$SUFFIX $k $LAMBDA_AT_K"); done
for l in $LAMBDAS; do CONFIGS+=("k${K_AT_LAMBDA}_l${l}$SUFFIX $K_AT_LAMBDA $l"); done
declare -A SEEN
for c in "${CONFIGS[@]}"; do
  name=${c%% *}
  [ -n "${SEEN[$name]:-}" ] && continue
  SEEN[$name]=1
  # shellcheck disable=SC2086
  run_config $c
done

echo
echo "| run | k | λ | moving crop PSNR | SSIM | LPIPS | static crop PSNR (mean) | consistency RMS |"
echo "|---|---|---|---|---|---|---|---|"
first=1
for name in "${!SEEN[@]}"; do echo "$name"; done | sort | while read -r name; do
  r="$OUT/$name/results.json"
  k=$(sed -n 's/^k = //p' "$OUT/$name/config.toml")
  l=$(sed -n 's/^lambda = //p' "$OUT/$name/config.toml")
  if [ $first = 1 ]; then
    jq -r '.baseline | "| baseline | – | – | \(.moving_object_crop.mean.psnr*100|round/100) | \(.moving_object_crop.mean.ssim*1000|round/1000) | \(.moving_object_crop.mean.lpips*1000|round/1000) | \([.static_object_crops[].mean.psnr] | add/length*100|round/100) | \(.deformation_consistency_rms*1000|round/1000) |"' "$r"
    first=0
  fi
  jq -r --arg n "$name" --arg k "$k" --arg l "$l" '.semdynreg | "| \($n) | \($k) | \($l) | \(.moving_object_crop.mean.psnr*100|round/100) | \(.moving_object_crop.mean.ssim*1000|round/1000) | \(.moving_object_crop.mean.lpips*1000|round/1000) | \([.static_object_crops[].mean.psnr] | add/length*100|round/100) | \(.deformation_consistency_rms*1000|round/1000) |"' "$r"
done
