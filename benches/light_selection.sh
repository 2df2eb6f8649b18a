#!/bin/bash
# Equal-time light selection: the light hierarchy (`light_selection=tree`)
# against power sampling (`power`) in the path tracer, 160x120, relMSE of
# luminance against the mean of a 1024-spp render by each, runs alternated,
# CPU seconds (user + sys) of each whole `chiaro render` process.
#
#   CHIARO_ASSETS=/work/shared/assets benches/light_selection.sh [SEEDS] [OUT]
#
# Scenes: DamagedHelmet.glb as imported (15,452 emissive triangles beside
# the studio environment and key light), the helmet lit by its emissive
# triangles only (a TOML with the glb as its one object), and
# EmissiveStrengthTest.glb (60 emissive triangles). Prints one line per
# scene and sample count (benches/light_selection.py).
set -eu
SEEDS=${1:-5}
OUT=${2:-/tmp/light_selection}
ASSETS=${CHIARO_ASSETS:-/work/shared/assets}
BIN=${CHIARO_BIN:-$(dirname "$0")/../target/release/chiaro}
G=$ASSETS/khronos-gltf-sample-assets
mkdir -p "$OUT"
cat > "$OUT/helmet-emissive.toml" <<TOML
[render]
technique = "path"
width = 160
height = 120
[camera]
eye = [0, 0, 3]
look_at = [0, 0, 0]
up = [0, 1, 0]
fov = 45
[[object]]
mesh = "$G/DamagedHelmet/glTF-Binary/DamagedHelmet.glb"
TOML
declare -A S=([helmet]=$G/DamagedHelmet/glTF-Binary/DamagedHelmet.glb
  [helmetemit]=$OUT/helmet-emissive.toml
  [emissive]=$G/EmissiveStrengthTest/glTF-Binary/EmissiveStrengthTest.glb)
: > "$OUT/times.tsv"
uptime
for s in helmet helmetemit emissive; do
  for m in power tree; do
    "$BIN" render "${S[$s]}" -t path --width 160 --height 120 --samples 1024 --seed 900 \
      --set light_selection=$m -o "$OUT/ref-$s-$m.exr" > /dev/null 2>&1
  done
  for spp in 16 64; do for seed in $(seq 1 "$SEEDS"); do for m in power tree; do
    /usr/bin/time -f "%U %S" -o "$OUT/t.txt" "$BIN" render "${S[$s]}" -t path --width 160 \
      --height 120 --samples $spp --seed $seed --set light_selection=$m \
      -o "$OUT/r-$s-$spp-$seed-$m.exr" > /dev/null 2>&1
    printf '%s\t%s\t%s\t%s\t%s\n' $s $spp $seed $m "$(awk '{print $1+$2}' "$OUT/t.txt")" >> "$OUT/times.tsv"
  done; done; done
done
uptime
python3 "$(dirname "$0")/light_selection.py" "$OUT"
