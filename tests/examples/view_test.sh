#!/usr/bin/env bash
# `shadowtile view` as an engine renders: a served city pack, the GPU rasterizer of
# examples/raster on lavapipe, one camera held for every frame, tiles streamed only through
# its fragment shader's feedback. Checks: exit 0, one non-empty PNG per frame, the holes
# falling to none as tiles arrive, the last frame's lookups equal to the CPU twin's bit for
# bit (the shader's float light transform over the client's cache at the receivers the
# fragment shader used: --twin), and the last frame
# beside `shadowtile render` from the same camera (Embree primary rays, the CPU's lookups)
# differing in few pixels (silhouettes: rasterized against ray-traced edges); the Khronos
# validation layer silent throughout (--validation).
# Usage: view_test.sh SHADOWTILE WORKDIR
set -uo pipefail
st=$1 work=$2
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAIL view: $*"; exit 1; }
. "$here/served_city.sh"
cam="pos=140,110,50,target=0,20,0,fov=50" size=160x90 frames=6
timeout 300 "$st" view --server "127.0.0.1:$port" --map city --scene "$scene" --camera "$cam" --size $size \
  --frames $frames --fps 4 --pcf 3 --device llvmpipe --twin --validation --out "$work/view" >"$work/view.txt" 2>&1
rc=$?
(( rc == 0 )) || { cat "$work/view.txt"; fail "view exited $rc"; }
pngs=$(find "$work/view" -name 'frame_*.png' -size +0 | wc -l)
[[ "$pngs" -eq $frames && -s "$work/view/contact_sheet.png" ]] || { cat "$work/view.txt"; fail "$pngs PNG frames, expected $frames"; }
# The per-frame rows: frame, gpu ms, shade ms, host us, path us, requested, holes, hole %, resident.
holes=$(awk '$1 ~ /^[0-9]+$/ && NF == 9 {print $7}' "$work/view.txt")
first=$(head -n 1 <<<"$holes") last=$(tail -n 1 <<<"$holes")
[[ -n "$first" && -n "$last" ]] || { cat "$work/view.txt"; fail "no per-frame rows"; }
(( first > 0 && last == 0 )) || { cat "$work/view.txt"; fail "holes did not fall to none ($first -> $last)"; }
grep -qx "validation: 0 messages" "$work/view.txt" || { cat "$work/view.txt"; fail "the validation layer reported"; }
grep -qE "^twin: last frame's [1-9][0-9]* lookups against the CPU's: 0 differ .* holes in that frame 0$" "$work/view.txt" ||
  { cat "$work/view.txt"; fail "the fragment shader's lookups differ from the CPU twin's"; }
"$st" render --server "127.0.0.1:$port" --map city --scene "$scene" --camera "$cam" --size $size --pcf 3 --filter \
  -o "$work/render.exr" >"$work/render.txt" 2>&1 || { cat "$work/render.txt"; fail "render"; }
python3 "$here/png_compare.py" "$work/view/frame_000$((frames - 1)).png" "$work/render.png" 2 ||
  fail "the last frame differs from render's"
echo "view: $pngs frames, holes $first -> $last, equal to the CPU twin, beside render: $(python3 "$here/png_compare.py" "$work/view/frame_000$((frames - 1)).png" "$work/render.png" 2)"
