#!/usr/bin/env bash
# Renders the gallery: every technique on every shipped scene, small, with
# each scene's own settings (only the size is changed), plus the index
# docs/gallery/README.md and scenes.sha256, the hashes of the scene files it
# was made from (.ci/run checks them, so a changed scene needs a new gallery).
# Usage: docs/gallery/make.sh [WIDTH HEIGHT]   (default 192 144)
set -euo pipefail
cd "$(dirname "$0")/../.."
W=${1:-192}
H=${2:-144}
OUT=docs/gallery
TECHNIQUES=(preview flat gouraud phong whitted radiosity hybrid path)
cargo build --release -q -p chiaro-cli
BIN=target/release/chiaro
rm -f "$OUT"/*.png
{
  echo "# Gallery"
  echo
  echo "Every technique on every shipped scene at ${W}x${H}, with the scene's own"
  echo "settings. Made by \`docs/gallery/make.sh\`; the seconds are wall time on the"
  echo "machine that made it ($(nproc) cores)."
  echo
  printf '| scene |'
  for t in "${TECHNIQUES[@]}"; do printf ' %s |' "$t"; done
  echo
  printf '|---|'
  for _ in "${TECHNIQUES[@]}"; do printf -- '---|'; done
  echo
  for scene in scenes/*.toml; do
    name=$(basename "$scene" .toml)
    printf '| `%s` |' "$name"
    for t in "${TECHNIQUES[@]}"; do
      png="$name-$t.png"
      start=$(date +%s.%N)
      "$BIN" render "$scene" --technique "$t" --width "$W" --height "$H" -o "$OUT/$png" 2>/dev/null
      secs=$(awk "BEGIN { print $(date +%s.%N) - $start }")
      printf ' ![%s %s](%s)<br>%.1f s |' "$name" "$t" "$png" "$secs"
    done
    echo
  done
} > "$OUT/README.md.tmp"
mv "$OUT/README.md.tmp" "$OUT/README.md"
sha256sum scenes/*.toml > "$OUT/scenes.sha256"
echo "gallery: $(ls "$OUT"/*.png | wc -l) images in $OUT"
