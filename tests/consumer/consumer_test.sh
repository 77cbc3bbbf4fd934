#!/usr/bin/env bash
# The client as a game gets it: install into a temporary prefix, then build a C++ consumer
# and the C example with find_package(shadowtile) twice, against the static libraries and
# against libshadowtile.so (-Dshadowtile_SHARED=ON), where Embree, assimp, OpenEXR and
# Boost cannot be found (and for the shared library neither OpenSSL, zlib, Threads nor
# pkg-config), run them against a loopback shadowtile-server, and compare every answer of
# one level, and the C example's visibility of a batch of points, with the pack read
# locally. The C example is also built from pkg-config's shadowtile.pc alone.
#   consumer_test.sh BUILD_DIR SOURCE_DIR SHADOWTILE SERVER PACK_PROBE TMP SANITIZE
set -euo pipefail
build=$1 src=$2 st=$3 server=$4 probe=$5 tmp=$6 sanitize=$7
work="$tmp/consumer.$$"
rm -rf "$work" && mkdir -p "$work"
server_pid=""
cleanup() { [[ -n "$server_pid" ]] && kill "$server_pid" 2>/dev/null; wait 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "FAIL consumer: $*"; exit 1; }

prefix="$work/prefix"
cmake --install "$build" --prefix "$prefix" >/dev/null
headers=$(cd "$prefix/include" && find . -type f | sort | tr '\n' ' ')
gpu=OFF
[[ -f "$prefix/include/shadowtile/gpu.hpp" ]] && gpu=ON
want_headers="./shadowtile/cache_view.hpp ./shadowtile/client.hpp ./shadowtile/export.h "
[[ $gpu == ON ]] && want_headers+="./shadowtile/gpu.hpp "
want_headers+="./shadowtile/shadowtile.h "
[[ $gpu == ON ]] && want_headers+="./shadowtile/vk_setup.hpp "
[[ "$headers" == "$want_headers" ]] || fail "installed headers are not just the public ones: $headers"
[[ $gpu == OFF || -f "$prefix/share/shadowtile/shaders/shadowtile.glsl" ]] || fail "shadowtile.glsl not installed"
# Every file the headers send their reader to is installed under share/doc/shadowtile.
for f in $(grep -ohE '\b(client|proto|tiles)/[A-Za-z_/]+\.(md|hpp)\b' "$prefix/include/shadowtile/"* | sort -u); do
  [[ -f "$prefix/share/doc/shadowtile/$f" ]] || fail "the headers cite $f, not installed under share/doc/shadowtile"
done
so=$(cd "$prefix/lib" && ls libshadowtile.so.*.* 2>/dev/null | head -1)
[[ -n "$so" && -L "$prefix/lib/libshadowtile.so" ]] || fail "no libshadowtile.so.VERSION and libshadowtile.so link in $prefix/lib"
[[ -f "$prefix/lib/pkgconfig/shadowtile.pc" ]] || fail "no lib/pkgconfig/shadowtile.pc"

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
"$probe" "$work/city.pack" $level >"$work/want.txt"
lines=$(wc -l <"$work/want.txt")
[[ "$lines" -eq $((512 * 512)) ]] || fail "reference has $lines lines"
"$probe" "$work/city.pack" points 2000 11 >"$work/points.txt"
"$probe" "$work/city.pack" visibility <"$work/points.txt" >"$work/want_points.txt"

# run_c_client NAME BINARY: the C example's answers for the points equal the pack's.
run_c_client() {
  timeout 120 "$2" 127.0.0.1 "$port" city 256 <"$work/points.txt" >"$work/$1.txt" 2>"$work/$1.err" ||
    { cat "$work/$1.err"; fail "$1 exited $?"; }
  cut -d' ' -f1 "$work/$1.txt" | cmp -s - "$work/want_points.txt" || fail "$1: answers differ from the pack's"
}

# variant NAME CMAKE_ARGS...: configure, build, check the links, run both programs.
variant() {
  local name=$1
  shift
  local dir="$work/build-$name"
  cmake -S "$src/tests/consumer" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_PREFIX_PATH="$prefix" -DCONSUMER_SANITIZE="$sanitize" \
    -DCMAKE_DISABLE_FIND_PACKAGE_embree=TRUE -DCMAKE_DISABLE_FIND_PACKAGE_assimp=TRUE \
    -DCMAKE_DISABLE_FIND_PACKAGE_OpenEXR=TRUE "$@" >"$work/configure-$name.log" 2>&1 ||
    { cat "$work/configure-$name.log"; fail "$name: configure"; }
  cmake --build "$dir" >"$work/build-$name.log" 2>&1 || { cat "$work/build-$name.log"; fail "$name: build"; }
  for exe in consumer c_client; do
    if readelf -d "$dir/$exe" | grep -Eiq 'NEEDED.*(embree|assimp|openexr|Imath)'; then
      fail "$name: $exe links a baking library: $(readelf -d "$dir/$exe" | grep NEEDED)"
    fi
  done
  timeout 120 "$dir/consumer" 127.0.0.1 "$port" city $level >"$work/got.txt" || fail "$name: consumer exited $?"
  cmp -s "$work/got.txt" "$work/want.txt" || { diff "$work/got.txt" "$work/want.txt" | head -5; fail "$name: answers differ from the pack"; }
  run_c_client "c_client-$name" "$dir/c_client"
}

# Static: Boost (the client's build dependency) is unfindable; pkg-config is not disabled
# only because CMake's own FindOpenSSL calls it when present.
variant static -Dshadowtile_SHARED=OFF -DCMAKE_DISABLE_FIND_PACKAGE_Boost=TRUE -DCONSUMER_GPU="$gpu"
if [[ $gpu == ON ]]; then
  VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json SHADOWTILE_VK_DEVICE=llvmpipe XDG_RUNTIME_DIR="$work" \
    timeout 120 "$work/build-static/consumer_gpu" 127.0.0.1 "$port" city $level >"$work/got_gpu.txt" || fail "consumer_gpu exited $?"
  cmp -s "$work/got_gpu.txt" "$work/want.txt" || { diff "$work/got_gpu.txt" "$work/want.txt" | head -5; fail "GPU answers differ from the pack"; }
  [[ -f "$work/build-static/shade.frag.spv" ]] || fail "the fragment shader over the installed shadowtile.glsl did not compile"
  [[ -f "$work/build-static/shade_texel.frag.spv" ]] ||
    fail "the fragment shader over the installed shadowtile.glsl with ST_TEXEL_BUFFERS did not compile"
  echo "consumer_gpu: $lines texels of level $level on the GPU equal the pack's, bit for bit"
fi
readelf -d "$work/build-static/consumer" | grep -q 'NEEDED.*libshadowtile' && fail "static: consumer needs libshadowtile.so"

variant shared -Dshadowtile_SHARED=ON -DCMAKE_DISABLE_FIND_PACKAGE_Boost=TRUE -DCMAKE_DISABLE_FIND_PACKAGE_PkgConfig=TRUE \
  -DCMAKE_DISABLE_FIND_PACKAGE_OpenSSL=TRUE -DCMAKE_DISABLE_FIND_PACKAGE_ZLIB=TRUE -DCMAKE_DISABLE_FIND_PACKAGE_Threads=TRUE
for exe in consumer c_client; do
  needed=$(readelf -d "$work/build-shared/$exe" | grep NEEDED)
  grep -q "libshadowtile\.so\.[0-9]" <<<"$needed" || fail "shared: $exe does not need libshadowtile.so.N: $needed"
  grep -Eq 'libssl|libcrypto|libdeflate|libz\.' <<<"$needed" && fail "shared: $exe links the library's dependencies itself: $needed"
done

# pkg-config alone (no CMake): the C example from shadowtile.pc.
if command -v pkg-config >/dev/null; then
  flags=$(PKG_CONFIG_PATH="$prefix/lib/pkgconfig" pkg-config --cflags --libs shadowtile)
  san=()
  [[ "$sanitize" == ON ]] && san=(-fsanitize=address,undefined)
  cc -std=c99 -Wall -Wextra -Werror -pedantic "${san[@]}" "$src/examples/c_client.c" $flags \
    -Wl,-rpath,"$prefix/lib" -o "$work/c_client-pc" || fail "cc with pkg-config's flags ($flags)"
  run_c_client c_client-pkgconfig "$work/c_client-pc"
fi
echo "consumer: static and shared: $lines texels of level $level and $(wc -l <"$work/points.txt") points equal the pack's, bit for bit"
