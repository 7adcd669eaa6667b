#!/bin/bash
# The viewer's next frame after its lamp is turned by ANGLE degrees about the vertical (the F
# and lobes still walked for the lamp where it was) against a fresh render of the scene the
# viewer saves right then (the lamp where it was turned), on the default scene. Needs Xvfb.
#   docs/experiments/stale-lamp.sh 0 2 5 10 30
#   EXTRA="--walk-paths 7496" docs/experiments/stale-lamp.sh 2
set -u
B=${B:-target/release/translucent}
W=${W:-/tmp/stale-lamp}
export VK_DRIVER_FILES=${VK_DRIVER_FILES:-/usr/share/vulkan/icd.d/lvp_icd.$(uname -m).json}
Xvfb :77 -screen 0 1280x1024x24 -nolisten tcp & X=$!
trap 'kill $X' EXIT
sleep 1
for A in "$@"; do
  D=$W/$A; rm -rf "$D"; mkdir -p "$D"
  DISPLAY=:77 $B view --script "frames 2; light $A 0; frames 1; screenshot stale; save-scene moved; quit" \
    --cache "$W/cache" --out "$D" ${EXTRA:-} > "$D/view.log" 2>&1 || { echo "view failed: $D/view.log"; continue; }
  $B render --frames 1 --cache "$W/cache" --out "$D/render" "$D/moved.toml" > "$D/render.log" 2>&1 \
    || { echo "render failed: $D/render.log"; continue; }
  echo "turn $A: $($B compare --out "$D/cmp" "$D/stale.exr" "$D/render/render.exr" | grep "relative RMS" | tr -s ' ' | tr '\n' ' ')"
done
