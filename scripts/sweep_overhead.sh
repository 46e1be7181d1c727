#!/usr/bin/env bash
# What `semdynreg sweep` adds to a run (README, "Sweeps": cost): one tiny run through `train`
# directly, through `train` + `render` + `eval`, and through `sweep --backend local`, REPS
# times interleaved; prints each repetition (take the medians).
#   BIN=target/release/semdynreg REPS=7 ITERS=200 scripts/sweep_overhead.sh
set -euo pipefail
BIN=${BIN:-target/release/semdynreg}
W=${W:-$(mktemp -d)}
REPS=${REPS:-5}
ITERS=${ITERS:-200}
mkdir -p "$W"
export SEMDYNREG_OFFLINE=1 SEMDYNREG_WEIGHTS=/nonexistent
"$BIN" synth toycars --out "$W/scene" --width 64 --height 48 --frames 24 >/dev/null 2>&1
printf '[init]\nrandom_points = 2000\n' > "$W/c.toml"
cat > "$W/grid.toml" <<G
modes = ["baseline"]
iters = $ITERS
[[scenes]]
name = "s"
path = "scene"
[config.init]
random_points = 2000
G
t() { local s e; s=$(date +%s.%N); "$@" >/dev/null 2>&1; e=$(date +%s.%N); echo "$e - $s" | bc; }
for i in $(seq 1 "$REPS"); do
  a=$(t "$BIN" train "$W/scene" --out "$W/a$i" --iters "$ITERS" --config "$W/c.toml" --no-reg)
  b0=$(t "$BIN" train "$W/scene" --out "$W/b$i" --iters "$ITERS" --config "$W/c.toml" --no-reg)
  b1=$(t "$BIN" render "$W/b$i" --split test)
  b2=$(t "$BIN" eval "$W/b$i" --split test --no-lpips)
  c=$(t "$BIN" sweep "$W/grid.toml" --out "$W/c$i")
  echo "rep $i: train $a | train+render+eval $(echo "$b0 + $b1 + $b2" | bc) (train $b0) | sweep $c"
done
