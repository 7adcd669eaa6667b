#!/usr/bin/env bash
# Every model on the four truth scenes against their volumetric truth: relative RMS after 4x4
# binning (the truth's noise removed), frame time (GPU median over 20 frames) and
# preprocessing time, one markdown row per scene and model.
#
# Usage: tools/models_vs_truth.sh [TRUTH_ROOT] [OUT]
#   TRUTH_ROOT/SCENE/truth/{truth,noise}.exr must exist for each SCENE of assets/scenes/truth
#   (made by `translucent truth assets/scenes/truth/SCENE.toml --spp 256 --out
#   TRUTH_ROOT/SCENE/truth`, 1-7 minutes each on 2 cores); default out/t256.
# Needs a release build (cargo build --release) and a Vulkan device (lavapipe in CI).
set -euo pipefail
cd "$(dirname "$0")/.."
root="${1:-out/t256}"
out="${2:-out/models}"
bin=./target/release/translucent
echo "| scene | model | vs truth (R / G / B) | frame | thickness + single | preprocessing |"
echo "|---|---|---|---|---|---|"
for s in bunny-skimmilk bunny-marble sphere-ketchup slab-backlit; do
  for m in dipole halfspace halfspace-single; do
    o="$out/$m/$s"
    mkdir -p "$o"
    pre=$($bin precompute "assets/scenes/truth/$s.toml" --model "$m" --no-cache --cache "$out/cache" 2>&1 |
      grep '^time:' | sed 's/^time: //')
    $bin render "assets/scenes/truth/$s.toml" --model "$m" --frames 20 --cache "$out/cache" \
      --out "$o/render" > "$o/render.log" 2>&1
    frame=$(grep 'frame: GPU median' "$o/render.log" | sed 's/frame: GPU median \([0-9.]*\) ms.*/\1/')
    extra=$(python3 -c "import json,sys; j=json.load(open(sys.argv[1])); print(' + '.join(f\"{p['median_ms']:.1f}\" for p in j['passes'] if p['name'] in ('thickness', 'single')) or '-')" "$o/render/timings.json")
    $bin compare "$o/render/render.exr" "$root/$s/truth/truth.exr" \
      --noise "$root/$s/truth/noise.exr" --out "$o/compare" > "$o/compare.log" 2>&1
    err=$(grep '4x4 bins' "$o/compare.log" | sed 's/.*relative RMS \([0-9.]* \/ [0-9.]* \/ [0-9.]*\) %.*/\1/')
    echo "| $s | $m | $err % | $frame ms | $extra | $pre |"
  done
done
