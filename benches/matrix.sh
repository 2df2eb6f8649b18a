#!/usr/bin/env bash
# The technique-by-scene performance matrix: every technique on every shipped
# scene and on three glTF sample models, one process per cell (so the time
# and peak RSS are that cell's), with the scene's defaults at WIDTHxHEIGHT.
# Each cell is stopped after LIMIT seconds (shown as "> LIMIT"). Prints the
# Markdown for BENCHMARKS.md: machine, load, date, commit, then one table of
# wall seconds / CPU seconds / peak RSS per cell.
#
#   benches/matrix.sh                        # 640x480, 120 s per cell
#   WIDTH=320 HEIGHT=240 LIMIT=60 benches/matrix.sh
#   MODELS=0 benches/matrix.sh               # shipped scenes only
#   TECHS="radiosity hybrid" SCENES="scenes/spotlights.toml" benches/matrix.sh
#   BIN=/tmp/chiaro-old benches/matrix.sh    # another build, not rebuilt
#
# The glTF models are read from ASSETS (default: the Khronos folder of the
# test assets named by $CHIARO_ASSETS; not part of
# the repository); models that are not there are left out of the table.
set -u
cd "$(dirname "$0")/.."
WIDTH=${WIDTH:-640}
HEIGHT=${HEIGHT:-480}
LIMIT=${LIMIT:-120}
MODELS=${MODELS:-1}
ASSETS=${ASSETS:-${CHIARO_ASSETS:-assets-not-set}/khronos-gltf-sample-assets}
TECHS=${TECHS:-"preview flat gouraud phong whitted radiosity hybrid path"}
# BIN=path: time that binary instead of building this tree's.
if [ -z "${BIN:-}" ]; then
  BIN=target/release/chiaro
  nice cargo build --release -p chiaro-cli >&2 || exit 1
fi

if [ -z "${SCENES:-}" ]; then
  SCENES=$(ls scenes/*.toml)
  if [ "$MODELS" = 1 ]; then
    # DamagedHelmet and the two largest sample models by triangle count
    # (1.04 M and 129 k triangles).
    for m in DamagedHelmet/glTF-Binary/DamagedHelmet.glb \
      MetalRoughSpheresNoTextures/glTF-Binary/MetalRoughSpheresNoTextures.glb \
      TransmissionTest/glTF-Binary/TransmissionTest.glb; do
      [ -f "$ASSETS/$m" ] && SCENES="$SCENES $ASSETS/$m"
    done
  fi
fi

OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT

echo "Machine: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), $(nproc) cores, $(free -g | awk '/Mem:/{print $2}') GiB."
echo "Date: $(date -u '+%Y-%m-%d %H:%M UTC'); binary $BIN; tree at commit $(git rev-parse --short HEAD)$(git diff --quiet HEAD -- crates || echo ' (with uncommitted changes)')."
echo "Load average before: $(cut -d' ' -f1-3 /proc/loadavg)."
echo "Size ${WIDTH}x${HEIGHT}, scene defaults otherwise; per cell: wall s / CPU s / peak RSS MB; '> $LIMIT / c' = stopped at the limit, having used c CPU seconds; 'error' = refused (message below)."
echo
header="| scene |"
rule="|---|"
for t in $TECHS; do
  header="$header $t |"
  rule="$rule---|"
done
echo "$header"
echo "$rule"
errors=""
for s in $SCENES; do
  row="| $(basename "$s") |"
  for t in $TECHS; do
    log="$OUT/log"
    /usr/bin/time -f '%e %U %S %M' -o "$OUT/time" \
      timeout "$LIMIT" "$BIN" render "$s" -t "$t" --width "$WIDTH" --height "$HEIGHT" \
      -o "$OUT/cell.png" >"$log" 2>&1
    rc=$?
    # GNU time puts "Command exited with non-zero status" first on failure.
    read -r wall user sys rss < <(tail -n 1 "$OUT/time") || true
    if [ "$rc" = 124 ]; then
      # (GNU time's peak RSS is then the timeout wrapper's: left out.)
      cell=$(awk -v u="$user" -v s="$sys" -v l="$LIMIT" \
        'BEGIN { printf "> %d / %.0f", l, u + s }')
    elif [ "$rc" != 0 ]; then
      cell="error"
      errors="$errors
- $(basename "$s") $t: $(tail -n 1 "$log")"
    else
      cell=$(awk -v w="$wall" -v u="$user" -v s="$sys" -v r="$rss" \
        'BEGIN { printf "%.2f / %.2f / %d", w, u + s, r / 1024 }')
    fi
    row="$row $cell |"
  done
  echo "$row"
done
echo
echo "Load average after: $(cut -d' ' -f1-3 /proc/loadavg)."
[ -n "$errors" ] && echo "Errors:$errors"
exit 0
