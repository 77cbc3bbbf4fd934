#!/usr/bin/env bash
# examples/engine_raster as an engine runs it: a served city pack, the example's own Vulkan
# device (lavapipe), tiles streamed only through its fragment shader's feedback. Checks:
# exit 0, one non-empty PNG per frame, and holes falling as tiles arrive (the last frame has
# fewer pixels answered from coarser levels than the first).
# Usage: engine_raster_test.sh SHADOWTILE ENGINE_RASTER WORKDIR
set -uo pipefail
st=$1 raster=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAIL engine_raster: $*"; exit 1; }
. "$(dirname "$0")/served_city.sh"
frames=6
timeout 300 "$raster" --server "127.0.0.1:$port" --map city --scene "$scene" --size 160x90 \
  --frames $frames --frame-ms 300 --orbit 0 --device llvmpipe --validation --out "$work/frames" >"$work/out.txt" 2>&1
rc=$?
(( rc == 0 )) || { cat "$work/out.txt"; fail "exited $rc"; }
grep -qx "validation: 0 messages" "$work/out.txt" || { cat "$work/out.txt"; fail "the validation layer reported"; }
pngs=$(find "$work/frames" -name '*.png' -size +0 | wc -l)
[[ "$pngs" -ge $frames ]] || { cat "$work/out.txt"; fail "$pngs PNG frames written, expected $frames"; }
# The per-frame table: frame, tile B, page B, feedback B, fb tiles, requested, holes, gpu ms, shade ms.
holes=$(awk '$1 ~ /^[0-9]+$/ && NF == 9 {print $7}' "$work/out.txt")
first=$(head -n 1 <<<"$holes") last=$(tail -n 1 <<<"$holes")
[[ -n "$first" && -n "$last" ]] || { cat "$work/out.txt"; fail "no per-frame table"; }
(( last < first || (first == 0 && last == 0) )) || { cat "$work/out.txt"; fail "holes did not fall ($first -> $last)"; }
echo "engine_raster: $pngs frames, holes $first -> $last"
