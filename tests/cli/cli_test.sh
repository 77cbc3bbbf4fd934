#!/usr/bin/env bash
# End-to-end checks of the shadowtile executable as a user runs it: every subcommand's
# happy path, exit codes, one-line errors on bad input, and `verify` catching a tile that
# was corrupted on purpose. Usage: cli_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
st="$1"
work="$2/cli_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
light="--light sun:azimuth=30,elevation=50"
scene="procedural:city,size=3"
check help 0 "bounds" -- "$st" --help
check usage 2 "" -- "$st" build
check bounds 0 "Mrays/s" -- "$st" bounds procedural:cube $light --resolution 256 -o b.exr
[[ -f b.exr && -f b.png ]] || { echo "FAIL bounds outputs missing"; fail=1; }
check bad-resolution 1 "power of two" -- "$st" bounds procedural:cube $light --resolution 1000 -o x.exr
check bad-light 1 "elevation" -- "$st" bounds procedural:cube --light sun:azimuth=3,elevation=0 --resolution 256 -o x.exr
check missing-scene 1 "nosuch.obj" -- "$st" bounds nosuch.obj $light --resolution 256 -o x.exr
check unknown-procedural 1 "teapot" -- "$st" bounds procedural:teapot $light --resolution 256 -o x.exr
# Hostile scene files (SECURITY.md "Reading files"): one line, fast; limits by flag.
printf 'OFF\n353535235358 6 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > oom.off
check hostile-off 1 "OFF header claims 353535235358 vertices" -- "$st" bounds oom.off $light --resolution 256 -o x.exr
printf 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n' > tri.off
check scene-limits-triangles 1 "triangles must be in \[1, 2\^32-1\]" -- "$st" build tri.off $light --resolution 256 -o x.pack -q --scene-limits triangles=0
check scene-limits-bad-key 1 "scene-limits: expected none or KEY=VALUE" -- "$st" bounds tri.off $light --resolution 256 -o x.exr --scene-limits colour=3
check scene-limits-raised 0 "1 triangles" -- "$st" bounds tri.off $light --resolution 256 -o t.exr --scene-limits memory=2048,seconds=120
check build 0 "html: skipped \(SHADOWTILE_HTML=0\)" -- "$st" build $scene $light --resolution 2048 --encoding dagmh -o city.pack --report build.json -q
# The tile bound's message names the real bounds (64 B .. 64 MiB), as --help does.
check tile-bytes-too-big 1 "outside \[64 B, 64 MiB\]" -- "$st" build $scene $light --resolution 256 --tile-bytes 134217728 -o big.pack -q
check tile-bytes-help 0 "64 MiB" -- "$st" build --help
[[ -f build.json && ! -f city.pack.tmp ]] || { echo "FAIL build outputs"; fail=1; }
check inspect 0 "exit-depths" -- "$st" inspect city.pack
check inspect-json 0 '"encoding": "dagmh"' -- "$st" inspect city.pack --json
# DAG-MH builds carry the pack dictionary by default (tiles/PACK.md "DAG-MH dictionary").
check inspect-dictionary 0 "dictionary   DAG-MH, .* inner nodes" -- "$st" inspect city.pack
check bad-dictionary-option 1 "dagmh-dictionary: expected on or off" -- "$st" build $scene $light --resolution 256 --dagmh-dictionary maybe -o x.pack -q
check bad-dagmh-tiles-option 1 "dagmh-tiles: expected mixed, exhaustive or dagmh" -- "$st" build $scene $light --resolution 256 --dagmh-tiles maybe -o x.pack -q
check bad-up-option 1 "up: expected y or z, got .x." -- "$st" bounds procedural:cube $light --resolution 256 --up x -o x.exr
# Real assets (Debian's assimp-testmodels, scripts/deps): bounds says which up axis it
# read and why; the default DAG-MH build (dictionary, mixed tiles) of a game model with
# open and closed parts, then verify proves every texel.
models=/usr/share/assimp/models
if [[ -d "$models" ]]; then
  check real-up-axis 0 "up axis z \(from the file's <up_axis>, turned by assimp\)" -- "$st" bounds "$models/Collada/teapots.DAE" $light --resolution 256 -o teapots.exr
  check real-build 0 "up axis y \(from the file's metadata\)" -- "$st" build "$models/FBX/spider.fbx" $light --resolution 1024 -o spider.pack
  check real-verify-all 0 "every texel of the built region" -- "$st" verify spider.pack "$models/FBX/spider.fbx" --all
else
  echo "skip real assets: $models missing (scripts/deps installs assimp-testmodels)"
fi
# Stack packs (a light set): build, inspect, verify every texel of every slice, export a slice.
# The 200-byte tile bound splits cells below the skip level (the default; the pack every
# later stack check reads, the GPU views included); --split-cells=false keeps the uniform cut.
stackl="--light sun-path:azimuth=170..185,elevation=50..52,samples=4"
check stack-build 0 "stack of 4 slices of 128\^2" -- "$st" build $scene $stackl --resolution 128 --tile-bytes 200 -o stack.pack -q
check stack-inspect 0 "light set    sun-path" -- "$st" inspect stack.pack
check stack-inspect-split 0 "features .*stack-split-cells" -- "$st" inspect stack.pack
check stack-build-uniform 0 "octree skip level 6 \(8192 cells\)" -- "$st" build $scene $stackl --resolution 128 \
  --tile-bytes 200 --split-cells=false -o stack_uniform.pack -q
check stack-verify 0 "every texel of all 4 slices" -- "$st" verify stack.pack $scene
check stack-export 0 "exported slice 2 level 6" -- "$st" export stack.pack --slice 2 --level 6 -o slice.exr
check stack-export-noslice 1 "stack pack: pass --slice" -- "$st" export stack.pack -o x.exr
# A stack pack drawn at a time (two slices blended) and soft (every sample averaged), each
# against rays traced toward the same samples with the same weights: under 1% of the
# receivers may differ.
scam="--camera pos=60,40,60,target=0,0,0 --size 96x54"
check stack-render-time 0 "slices 1 and 2 blended" -- "$st" render stack.pack --scene $scene $scam --time 0.5 -o st.exr
check stack-render-time-diff 0 "differing pixels: [0-9]+ of [1-9][0-9]+ receivers \(0\.[0-9]+%\)" -- \
  "$st" render stack.pack --scene $scene $scam --time 0.4 --diff -o st.exr
check stack-render-soft-diff 0 "differing pixels: [0-9]+ of [1-9][0-9]+ receivers \(0\.[0-9]+%\)" -- \
  "$st" render stack.pack --scene $scene $scam --soft --pcf 3 --filter --diff -o ss.exr
[[ -f ss.png && -f ss_traced.png && -f ss_diff.png ]] || { echo "FAIL stack-render outputs missing"; fail=1; }
check stack-render-both 1 "not both" -- "$st" render stack.pack --scene $scene $scam --time 0.5 --soft -o x.exr
check stack-render-bad-time 1 "time: expected a time in \[0, 1\]" -- \
  "$st" render stack.pack --scene $scene $scam --time 1.5 -o x.exr
# PCF takes one unit everywhere, the kernel side: 0, even and out-of-range sides are refused.
for side in 0 2 4 11; do
  check render-pcf-side-$side 1 "pcf: a PCF kernel side is odd, 1\.\.9 \(1: one tap, 3: 3x3, 5: 5x5, \.\.\.\), got $side" -- \
    "$st" render stack.pack --scene $scene $scam --pcf $side -o x.exr
done
check report-pcf-side-1 1 "pcf: a PCF kernel side is odd, 3\.\.9 \(3: 3x3, 5: 5x5, \.\.\.\), got 1" -- \
  "$st" report --scene $scene --light sun:azimuth=30,elevation=50 --pcf 1 --out rep-x
# An area light's stack in its default window frame (windowed spots): inspect names the
# frame, verify re-traces every texel of every slice, a slice exports, soft shadows render.
hair="procedural:hairball,count=12"
areal="--light area:pos=2,20,1,target=0,0,0,size=4,4,samples=4"
check area-build 0 "stack of 4 slices of 64\^2" -- "$st" build $hair $areal --resolution 64 --tile-bytes 4096 -o area.pack -q
check area-inspect 0 "light        spot-window:" -- "$st" inspect area.pack
check area-verify 0 "every texel of all 4 slices" -- "$st" verify area.pack $hair
check area-export 0 "exported slice 3 level 5" -- "$st" export area.pack --slice 3 --level 5 -o aslice.exr
check area-render-soft 0 "differing pixels: [0-9]+ of [1-9][0-9]+ receivers" -- \
  "$st" render area.pack --scene $hair --camera pos=3,3,3,target=0,0,0 --size 96x54 --soft --diff -o as.exr
# An area light over the city (viewed below: the GPU soft pass over perspective samples).
check area-city-build 0 "stack of 4 slices of 64\^2" -- "$st" build $scene \
  --light area:pos=60,250,40,target=0,0,0,size=40,40,samples=4,fov=70 --resolution 64 --tile-bytes 4096 -o areacity.pack -q
check area-window-refused 1 "use frame=translate" -- "$st" build $scene --light area:pos=20,60,10,target=0,0,0,size=8,8,samples=4 --resolution 64 -o x.pack -q
check stack-too-big 1 "exceeds the 2\^34 texels" -- "$st" build $scene --light sun-path:azimuth=1..2,elevation=50,samples=64 --resolution 64k -o x.pack -q
# A sun near the horizon over the city: the ground frame's square would be huge (refused
# before tracing); the orthographic frame takes it.
check stack-ground-stretch 1 "frame=ground: the lowest sun stretches the ground square" -- "$st" build $scene --light sun-path:azimuth=1..2,elevation=1..2,samples=2 --resolution 64 -o x.pack -q
check verify 0 "OK: 20[0-9]* random texels" -- "$st" verify city.pack $scene --samples 2000
# Every texel: the re-trace gives the build's canonical bounds bit for bit.
check verify-all 0 "OK: every texel of the built region \(2048 x 2048 = 4194304\)" -- "$st" verify city.pack $scene --all
# ... and the skip grid (4096 cells at K = 6, 1365 coarse values) against those texels'
# hulls: a finished pack keeps no cell intervals of its own.
check verify-all-grid 0 "^verify: 5461 skip grid values .* lie in the hulls" -- "$st" verify city.pack $scene --all
# A regions build (whole regions proven by their corners) and every texel of random squares.
check build-regions 0 "regions: .* texels proven by their corners" -- "$st" build $scene $light --resolution 2048 --skip-level 3 --encoding dagmh --raster-skip regions -o regions.pack
check verify-cells 0 "OK: every texel of 40 random 64\^2 squares \(163840 texels\)" -- "$st" verify regions.pack $scene --all --cells 40 --cell-side 64
check verify-cells-grid 0 "^verify: [1-3] skip grid values" -- "$st" verify regions.pack $scene --all --cells 3 --cell-side 256
check verify-cells-side 1 "cell-side 48 must be a power of two" -- "$st" verify regions.pack $scene --all --cells 4 --cell-side 48
# Against another scene every texel cannot hold: stops at the first 5 and names them.
check verify-all-mismatch 3 "FAILED: 5 texels break.*max-mismatches 5" -- "$st" verify city.pack procedural:city,size=2 --all --max-mismatches 5
# Static-geometry intervals on an open scene (one merged mesh of roofless walls and tilted
# plates over a slab): a pack feature, checked under its contract.
python3 - <<'PY'
import random
random.seed(3)
v, f = [(0, 0, 0), (0, 0, 40), (40, 0, 40), (40, 0, 0)], [(1, 2, 3), (1, 3, 4)]
for k in range(60):
    x, z, w, h, t = random.uniform(2, 36), random.uniform(2, 36), random.uniform(1, 3), random.uniform(1, 6), random.uniform(-1, 1)
    b = len(v)
    v += [(x, h, z), (x + w, h + t, z), (x + w, h + t, z + w), (x, h, z + w), (x, 0, z), (x + w, 0, z)]
    f += [(b + 1, b + 2, b + 3), (b + 1, b + 3, b + 4), (b + 5, b + 6, b + 2), (b + 5, b + 2, b + 1)]
with open("open_town.obj", "w") as o:
    o.write("o town\n" + "".join("v %g %g %g\n" % p for p in v) + "".join("f %d %d %d\n" % t for t in f))
PY
check build-static 0 "built static.pack" -- "$st" build open_town.obj $light --resolution 1024 --encoding mh --intervals static -o static.pack -q
check inspect-static 0 "static-intervals" -- "$st" inspect static.pack
check verify-static-contract 0 "static-geometry intervals: lossless for receivers that lie on surfaces" -- "$st" verify static.pack open_town.obj --all
check verify-static 0 "OK: every texel of the built region \(1024 x 1024" -- "$st" verify static.pack open_town.obj --all
# A rasterized static pack is re-traced under its own rule too (not the closed-object one).
check build-static-raster 0 "bounds by raster" -- "$st" build open_town.obj $light --resolution 256 --builder raster --intervals static -o static_raster.pack -q
check verify-static-raster 0 "OK: every texel of the built region \(256 x 256" -- "$st" verify static_raster.pack open_town.obj --all
# --raster-skip auto proves whole regions of static builds from 16K^2 up (128K^2 under the default rule).
check build-static-auto-regions 0 "skip regions" -- "$st" build open_town.obj $light --resolution 16k --intervals static --region 8064,8064,256,256 -o static16k.pack -q
check verify-static-auto-regions 0 "OK: every texel of the built region \(256 x 256" -- "$st" verify static16k.pack open_town.obj --all
check build-default-auto-exact 0 "skip exact" -- "$st" build open_town.obj $light --resolution 16k --region 8064,8064,256,256 -o default16k.pack -q
# A vsdag pack is checked against its slab contract at the depth resolution it recorded.
check build-vsdag 0 "built vsdag.pack" -- "$st" build $scene $light --resolution 512 --encoding vsdag --depth-bits 10 -o vsdag.pack -q
check inspect-vsdag 0 '"depth_bits": "10"' -- "$st" inspect vsdag.pack --json
check verify-vsdag 0 "every one within one of 2\^10 depth slabs of \[lo, hi\] \(vsdag contract\)" -- "$st" verify vsdag.pack $scene --all
check verify-vsdag-mismatch 3 "FAILED: 3 texels break the vsdag contract" -- "$st" verify vsdag.pack procedural:city,size=2 --all --max-mismatches 3
check bad-intervals 1 "intervals: expected default or static" -- "$st" build procedural:cube $light --resolution 256 --intervals sometimes -o x.pack -q
check export 0 "exported level 8" -- "$st" export city.pack --level 8 -o l8.exr
check export-bad-level 1 "exceeds" -- "$st" export city.pack --level 30 -o l.exr
# Deep shadow maps of partial occluders: a deep scanline EXR; a scene without any is refused.
check export-deep 0 "exported deep level 5 region 0,0,32x32" -- "$st" export --deep procedural:forest,trees=2,leaves=50,size=8,translucency=0.5 $light --level 5 --samples 2 -o deep.exr
[[ -f deep.exr ]] || { echo "FAIL export --deep output missing"; fail=1; }
check export-deep-opaque 1 "has no partial occluder" -- "$st" export --deep procedural:cube $light --level 4 -o d.exr
# Corrupt one byte inside the first tile payload: verify must fail and name the tile.
python3 - <<'PY'
import struct, zlib
data = bytearray(open("city.pack", "rb").read())
# Header: journal_offset at 200, index_offset at 224, tile_count at 232 (tiles/PACK.md).
index_offset, tile_count = struct.unpack_from("<QQ", data, 224)
assert tile_count > 0
if struct.unpack_from("<I", data, 20)[0] & (1 << 8):
    # Feature payloads_only: the first payload starts the journal section; the compact
    # index ("STIZ", size, zlib of the columns) holds its stored size after the n ids.
    payload = struct.unpack_from("<Q", data, 200)[0]
    size = struct.unpack_from("<I", zlib.decompress(bytes(data[index_offset + 8:])), 8 * tile_count)[0]
else:
    # The plain index: the first entry's payload offset at +8, stored size at +16.
    payload, size = struct.unpack_from("<QI", data, index_offset + 8)
data[payload + size // 2] ^= 0x40
open("corrupt.pack", "wb").write(data)
PY
check verify-corrupt 3 "FAILED.*tile" -- "$st" verify corrupt.pack $scene --samples 100
# Build parameters holding terminal controls (ESC, CR; CRCs fixed): inspect escapes them
# as --json does, so nothing raw reaches the terminal.
python3 - <<'PY'
import struct, zlib
data = bytearray(open("city.pack", "rb").read())
params_offset, params_size = struct.unpack_from("<QQ", data, 184)
blob = bytes(data[params_offset:params_offset + params_size])
for line in blob.split(b"\n"):
    key, _, value = line.partition(b"=")
    if len(value) >= 6:
        at = params_offset + blob.index(line) + len(key) + 1
        data[at:at + 6] = b"\x1b[2J\r!"
        break
else:
    raise SystemExit("no parameter value of 6 bytes")
struct.pack_into("<I", data, 240, zlib.crc32(data[params_offset:params_offset + params_size]))
struct.pack_into("<I", data, 252, zlib.crc32(data[0:252]))
open("controls.pack", "wb").write(data)
PY
check inspect-controls 0 'u001b\[2J\\r' -- "$st" inspect controls.pack
if "$st" inspect controls.pack | grep -q $'[\x1b\r]'; then echo "FAIL inspect-controls: raw control bytes printed"; fail=1; fi
check inspect-controls-json 0 'u001b\[2J\\r' -- "$st" inspect controls.pack --json
# A NaN light (header CRC fixed) once aborted verify inside Embree; garbage coarse levels
# (grid CRC fixed) were exported as they lay. Both are refused when the pack is opened.
python3 - <<'PY'
import struct, zlib
data = bytearray(open("city.pack", "rb").read())
nan = bytearray(data)
struct.pack_into("<d", nan, 40, float("nan"))
struct.pack_into("<I", nan, 252, zlib.crc32(nan[0:252]))
open("nan_light.pack", "wb").write(nan)
grid_offset, grid_size, index_offset = struct.unpack_from("<QQQ", data, 208)
skip = data[27]
compressed = struct.unpack_from("<I", data, 20)[0] & (1 << 7)  # feature compressed_grid: "STGZ", size, zlib
grid = data[grid_offset:grid_offset + grid_size]
if compressed:
    grid = bytearray(zlib.decompress(bytes(grid[8:])))
for i in range(((1 << (2 * skip)) - 1) // 3):
    struct.pack_into("<f", grid, 8 + 4 * i, -1000.0)
if compressed:
    grid = bytearray(struct.pack("<II", 0x5A475453, len(grid)) + zlib.compress(bytes(grid)))
data = data[:grid_offset] + grid + data[index_offset:]
struct.pack_into("<QQ", data, 216, len(grid), grid_offset + len(grid))
struct.pack_into("<I", data, 244, zlib.crc32(grid))
struct.pack_into("<I", data, 252, zlib.crc32(data[0:252]))
open("bad_coarse.pack", "wb").write(data)
PY
check verify-nan-light 1 "light.*not a finite number" -- "$st" verify nan_light.pack $scene --samples 100
check export-bad-coarse 1 "outside the depth range" -- "$st" export bad_coarse.pack --level 2 -o bad.exr
check truncated 1 "city|trunc|size" -- bash -c "head -c 1000 city.pack > short.pack && '$st' inspect short.pack"
# Serving with a catalog key and TLS: the key holder trusting the certificate is served;
# a client without the key is refused with a one-line error (exit 1), learning no map.
openssl rand -hex 32 > catalog.key
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 1 -subj /CN=localhost \
  -addext "subjectAltName=DNS:localhost,IP:127.0.0.1" -keyout tls.key -out tls.crt 2>/dev/null
"$st" serve city.pack --listen 127.0.0.1:0 --key-file catalog.key --tls-cert tls.crt --tls-key tls.key \
  2>serve.log &
spid=$!
port=$(port_of serve.log)
if [[ -z "$port" ]]; then echo "FAIL serve-keyed: no port in serve.log"; cat serve.log; fail=1
else
  check serve-keyed-load 0 "frames" -- "$st" load --server 127.0.0.1:$port --map city --cameras 2 \
    --duration 2 --rate 30 --key-file catalog.key --tls-ca tls.crt --tls-name localhost
  check serve-no-key 1 "auth_required" -- "$st" load --server 127.0.0.1:$port --map city --cameras 1 \
    --duration 1 --tls-ca tls.crt --tls-name localhost
  check bad-key-file 1 "catalog.short.*at least 16" -- bash -c "echo abc > catalog.short && '$st' load \
    --server 127.0.0.1:$port --map city --key-file catalog.short"
fi
kill $spid 2>/dev/null; wait $spid 2>/dev/null
grep -q "key required, TLS" serve.log || { echo "FAIL serve-keyed: banner lacks 'key required, TLS'"; fail=1; }
# A stack pack served: the load tester sweeps the time (the slices around it requested as
# it advances) or reads every slice (--soft); render draws it from the server.
"$st" serve stack.pack city.pack areacity.pack --listen 127.0.0.1:0 2>serve_stack.log &
spid=$!
port=$(port_of serve_stack.log)
if [[ -z "$port" ]]; then echo "FAIL serve-stack: no port in serve_stack.log"; cat serve_stack.log; fail=1
else
  check stack-load-sweep 0 "stack: slices / time +4 / 0.000..1.000 swept" -- "$st" load --server 127.0.0.1:$port \
    --map stack --cameras 2 --duration 1 --rate 30 --time-sweep 0..1
  check stack-load-soft 0 "soft \(every slice\)" -- "$st" load --server 127.0.0.1:$port --map stack --cameras 1 \
    --duration 0.5 --rate 30 --soft
  check stack-load-bad-sweep 1 "time-sweep: '0.2..3': expected a time in \[0, 1\]" -- "$st" load \
    --server 127.0.0.1:$port --map stack --time-sweep 0.2..3
  check stack-render-served 0 "differing pixels: [0-9]+ of [1-9][0-9]+ receivers \(0\.[0-9]+%\)" -- \
    "$st" render --server 127.0.0.1:$port --map stack --scene $scene $scam --time 0.5 --diff -o sr.exr
  # The headless viewer (GPU builds; lavapipe, a CPU Vulkan device): the sun sweeps over the
  # frames while the camera flies, the GPU pass blending the two slices around each time.
  # Mesa leaks at exit, so LeakSanitizer is off for these runs (ASan and UBSan stay on).
  lvp=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json
  if "$st" view --help >/dev/null 2>&1 && [[ -f $lvp ]]; then
    venv=(env VK_ICD_FILENAMES=$lvp "ASAN_OPTIONS=${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0")
    vargs=(view --server 127.0.0.1:$port --scene $scene --frames 3 --fps 30 --size 64x36 --device llvmpipe --cache-mb 4)
    check stack-view-sweep 0 "stack of 4 slices .* swept" -- "${venv[@]}" "$st" "${vargs[@]}" --map stack \
      --time-sweep 0..1 --out view_stack
    grep -q '"time1": 1.0' view_stack/view.json 2>/dev/null || { echo "FAIL stack-view-sweep: no time in view.json"; fail=1; }
    check stack-view-bad-sweep 1 "time-sweep: expected A..B, got '0.5'" -- "${venv[@]}" "$st" "${vargs[@]}" \
      --map stack --time-sweep 0.5
    check view-time-on-2d 1 "need a stack map" -- "${venv[@]}" "$st" "${vargs[@]}" --map city --time 0.5
    # The soft pass: every sample averaged on the GPU, for the sun path and the area light
    # (perspective samples).
    check stack-view-soft 0 "soft \(every sample averaged\)" -- "${venv[@]}" "$st" "${vargs[@]}" --map stack --soft \
      --out view_soft
    check area-view-soft 0 "[1-9][0-9]* requested from feedback" -- "${venv[@]}" "$st" "${vargs[@]}" --map areacity \
      --soft --out view_area
    check view-soft-and-time 1 "one of --time, --time-sweep, --soft" -- "${venv[@]}" "$st" "${vargs[@]}" --map stack \
      --soft --time 0.5
  fi
fi
kill $spid 2>/dev/null; wait $spid 2>/dev/null
check render-time-on-2d 1 "time and --soft need a stack pack" -- \
  "$st" render city.pack --scene $scene $scam --time 0.5 -o x.exr

# Kill a build mid-way (SIGKILL: no handler runs): nothing under the final name, and the
# same command with --resume completes it into the same pack as a one-go build.
res=8192
[[ "${SHADOWTILE_TEST_SCALE:-}" == small ]] && res=4096
kargs=(build "$scene" $light --resolution $res --encoding dagmh -q)
"$st" "${kargs[@]}" -o killed.pack >/dev/null 2>&1 &
pid=$!
for _ in $(seq 1 3000); do  # until some cells are on disk (at most 30 s)
  [[ -f killed.pack.tmp && $(stat -c %s killed.pack.tmp) -gt 65536 ]] && break
  kill -0 $pid 2>/dev/null || break
  sleep 0.01
done
kill -9 $pid 2>/dev/null
wait $pid 2>/dev/null
if [[ -f killed.pack ]]; then
  echo "FAIL kill-build: the build finished before it could be killed (or left a final pack)"; fail=1
elif [[ ! -f killed.pack.tmp ]]; then
  echo "FAIL kill-build: no killed.pack.tmp left to resume"; fail=1
else
  echo "ok   kill-build ($(stat -c %s killed.pack.tmp) bytes in killed.pack.tmp)"
  check resume 0 "[1-9][0-9]* resumed" -- "$st" "${kargs[@]}" -o killed.pack --resume
  check one-go 0 "built" -- "$st" "${kargs[@]}" -o onego.pack
  # Cells land in the journal in completion order, so offsets differ run to run; what
  # must match is every tile's bytes, the skip grid and the header's fields.
  if [[ ! -f killed.pack.tmp ]] && same_pack killed.pack onego.pack --ignore-params
  then echo "ok   resumed == one-go (same header fields, skip grid and tile bytes)"
  else echo "FAIL resumed pack differs from the one-go build"; fail=1; fi
  check verify-resumed 0 "OK" -- "$st" verify killed.pack "$scene" --samples 500
fi
exit $fail
