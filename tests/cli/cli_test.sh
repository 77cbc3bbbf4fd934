#!/usr/bin/env bash
# End-to-end checks of the shadowtile executable as a user runs it: every subcommand's
# happy path, exit codes, one-line errors on bad input, and `verify` catching a tile that
# was corrupted on purpose. Usage: cli_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
st="$1"
work="$2/cli_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
fail=0
check() {  # check NAME EXPECTED_EXIT PATTERN -- command...
  local name="$1" want="$2" pattern="$3"
  shift 4
  local out rc
  out="$("$@" 2>&1)"
  rc=$?
  if [[ "$rc" != "$want" ]]; then
    echo "FAIL $name: exit $rc, expected $want"; echo "$out" | tail -5; fail=1; return
  fi
  if [[ -n "$pattern" ]] && ! grep -qE "$pattern" <<<"$out"; then
    echo "FAIL $name: output lacks /$pattern/"; echo "$out" | tail -5; fail=1; return
  fi
  echo "ok   $name"
}
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
check build 0 "built city.pack" -- "$st" build $scene $light --resolution 2048 --encoding dagmh -o city.pack --report build.json -q
[[ -f build.json && ! -f city.pack.tmp ]] || { echo "FAIL build outputs"; fail=1; }
check inspect 0 "exit-depths" -- "$st" inspect city.pack
check inspect-json 0 '"encoding": "dagmh"' -- "$st" inspect city.pack --json
check verify 0 "OK: 20[0-9]* random texels" -- "$st" verify city.pack $scene --samples 2000
check export 0 "exported level 8" -- "$st" export city.pack --level 8 -o l8.exr
check export-bad-level 1 "exceeds" -- "$st" export city.pack --level 30 -o l.exr
# Corrupt one byte inside the first tile payload: verify must fail and name the tile.
python3 - <<'PY'
import struct
data = bytearray(open("city.pack", "rb").read())
# Header: index_offset at 224, tile_count at 232 (tiles/PACK.md); first index entry's
# payload offset at +8, stored size at +16.
index_offset, tile_count = struct.unpack_from("<QQ", data, 224)
assert tile_count > 0
payload, size = struct.unpack_from("<QI", data, index_offset + 8)
data[payload + size // 2] ^= 0x40
open("corrupt.pack", "wb").write(data)
PY
check verify-corrupt 3 "FAILED.*tile" -- "$st" verify corrupt.pack $scene --samples 100
check truncated 1 "city|trunc|size" -- bash -c "head -c 1000 city.pack > short.pack && '$st' inspect short.pack"
exit $fail
