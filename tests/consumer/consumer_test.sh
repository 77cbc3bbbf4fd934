#!/usr/bin/env bash
# The client as a game gets it: install into a temporary prefix, build a consumer with
# find_package(shadowtile) where Embree, assimp and OpenEXR cannot be found, run it
# against a loopback shadowtile-server, and compare every answer of one level with the
# pack read locally.
#   consumer_test.sh BUILD_DIR SOURCE_DIR SHADOWTILE SERVER PACK_PROBE TMP SANITIZE
set -euo pipefail
build=$1 src=$2 st=$3 server=$4 probe=$5 tmp=$6 sanitize=$7
work="$tmp/consumer.$$"
rm -rf "$work" && mkdir -p "$work"
server_pid=""
cleanup() { [[ -n "$server_pid" ]] && kill "$server_pid" 2>/dev/null; wait 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "FAIL consumer: $*"; exit 1; }

cmake --install "$build" --prefix "$work/prefix" >/dev/null
headers=$(cd "$work/prefix/include" && find . -type f | sort | tr '\n' ' ')
gpu=OFF
if [[ -f "$work/prefix/include/shadowtile/gpu.hpp" ]]; then gpu=ON; fi
want_headers="./shadowtile/cache_view.hpp ./shadowtile/client.hpp "
[[ $gpu == ON ]] && want_headers="./shadowtile/cache_view.hpp ./shadowtile/client.hpp ./shadowtile/gpu.hpp "
[[ "$headers" == "$want_headers" ]] || fail "installed headers are not just the public ones: $headers"
[[ $gpu == OFF || -f "$work/prefix/share/shadowtile/shaders/shadowtile.glsl" ]] || fail "shadowtile.glsl not installed"

cmake -S "$src/tests/consumer" -B "$work/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$work/prefix" -DCONSUMER_SANITIZE="$sanitize" -DCONSUMER_GPU="$gpu" \
  -DCMAKE_DISABLE_FIND_PACKAGE_embree=TRUE -DCMAKE_DISABLE_FIND_PACKAGE_assimp=TRUE \
  -DCMAKE_DISABLE_FIND_PACKAGE_OpenEXR=TRUE >"$work/configure.log" 2>&1 || { cat "$work/configure.log"; fail "configure"; }
cmake --build "$work/build" >"$work/build.log" 2>&1 || { cat "$work/build.log"; fail "build"; }
consumer="$work/build/consumer"
if readelf -d "$consumer" | grep -Eiq 'NEEDED.*(embree|assimp|openexr|Imath)'; then
  fail "the consumer links a baking library: $(readelf -d "$consumer" | grep NEEDED)"
fi

"$st" build procedural:city --light sun:azimuth=30,elevation=50 --resolution 512 --encoding dagmh \
  --tile-bytes 2048 -o "$work/city.pack" -q
"$server" "$work/city.pack" --listen 127.0.0.1:0 2>"$work/serve.log" &
server_pid=$!
port=""
for _ in $(seq 100); do
  port=$(grep -oE "on 127\.0\.0\.1:[0-9]+" "$work/serve.log" | head -1 | cut -d: -f2 || true)
  [[ -n "$port" ]] && break
  sleep 0.1
done
[[ -n "$port" ]] || { cat "$work/serve.log"; fail "no port in the server's banner"; }

level=9
timeout 120 "$consumer" 127.0.0.1 "$port" city $level >"$work/got.txt" || fail "consumer exited $?"
"$probe" "$work/city.pack" $level >"$work/want.txt"
lines=$(wc -l <"$work/want.txt")
[[ "$lines" -eq $((512 * 512)) ]] || fail "reference has $lines lines"
cmp -s "$work/got.txt" "$work/want.txt" || { diff "$work/got.txt" "$work/want.txt" | head -5; fail "answers differ from the pack"; }
echo "consumer: $lines texels of level $level equal the pack's, bit for bit"
if [[ $gpu == ON ]]; then
  VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json SHADOWTILE_VK_DEVICE=llvmpipe XDG_RUNTIME_DIR="$work" \
    timeout 120 "$work/build/consumer_gpu" 127.0.0.1 "$port" city $level >"$work/got_gpu.txt" || fail "consumer_gpu exited $?"
  cmp -s "$work/got_gpu.txt" "$work/want.txt" || { diff "$work/got_gpu.txt" "$work/want.txt" | head -5; fail "GPU answers differ from the pack"; }
  [[ -f "$work/build/shade.frag.spv" ]] || fail "the fragment shader over the installed shadowtile.glsl did not compile"
  echo "consumer_gpu: $lines texels of level $level on the GPU equal the pack's, bit for bit"
fi
