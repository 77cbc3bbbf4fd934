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
server_pid=""
cleanup() { [[ -n "$server_pid" ]] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null; }
trap cleanup EXIT
export VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json XDG_RUNTIME_DIR="$work"
[[ -f "$VK_ICD_FILENAMES" ]] || { echo "SKIP: no lavapipe ($VK_ICD_FILENAMES)"; exit 77; }
scene="procedural:city,size=3"
"$st" build "$scene" --light sun:azimuth=120,elevation=30 --resolution 1024 --tile-bytes 4096 \
  -o "$work/city.pack" -q || fail "build"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$st" serve "$work/city.pack" --listen "127.0.0.1:$port" >"$work/serve.log" 2>&1 &
server_pid=$!
for _ in $(seq 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$work/serve.log"; fail "the server died"; }
  sleep 0.1
done
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
