#!/usr/bin/env bash
# Packs with a deep part (tiles/PACK.md "Deep tiles"): a scene with partial occluders
# builds its opaque map and its deep tiles into one pack (feature deep_shadow), which
# inspect shows and verify checks (structure, the opaque map re-traced against the
# opaque casters, deep texels sampled afresh); a resumed build gives the same pack; a
# sharded build of such a scene is refused; a scene without partial occluders gets no
# deep part; a fog layer added to a scene spec builds and verifies. `build --deep-from` takes the deep map from the deep EXR `export --deep`
# wrote (verify then checks it against fresh samples) and refuses a file made for
# another light, a part of a map, another level or a file that is not deep.
# Usage: deep_pack_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
st="$1"
work="$2/deep_pack_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
hair="procedural:hairball,count=16,segments=24,transmit=0.5"
args=(build "$hair" --light sun:azimuth=40,elevation=60 --resolution 128 --encoding mh
      --deep-level 6 --deep-tile 8 --deep-samples 2)
check build-hair 0 "deep: 64\^2 texels" -- "$st" "${args[@]}" --tile-bytes 16384 -o hair.pack
check inspect-deep 0 "deep +64\^2 \(level 6\), [1-9][0-9]* of 64 tiles of 8\^2" -- "$st" inspect hair.pack
check inspect-json 0 "\"deep\"" -- "$st" inspect hair.pack --json
check verify-deep 0 "deep map: 256 texels sampled afresh" -- "$st" verify hair.pack "$hair" --samples 2000
check shard-refused 1 "partial occluders" -- "$st" "${args[@]}" --tile-bytes 16384 --shard 0/2 -o part.pack
check tiny-tiles 1 "over 256 bytes" -- "$st" "${args[@]}" --tile-bytes 256 -o tiny.pack
check build-boxes 0 "" -- "$st" build procedural:boxes --light sun:azimuth=40,elevation=60 --resolution 128 -q -o boxes.pack
check inspect-boxes 0 "" -- "$st" inspect boxes.pack
# Volumes in the scene spec: a fog layer over the boxes builds and verifies like any deep
# scene (the spec is the scene); a missing .vdb is one line.
fog="procedural:boxes+fog:density=0.2,height=1"
check build-fog 0 "volume 'fog' 1x32x1 voxels" -- "$st" build "$fog" --light sun:azimuth=40,elevation=60 \
  --resolution 64 --deep-level 5 --deep-tile 8 --deep-samples 2 -o fog.pack
check verify-fog 0 "deep map: 256 texels sampled afresh" -- "$st" verify fog.pack "$fog" --samples 500
check vdb-missing 1 "scene file not found: nothing.vdb" -- "$st" build "procedural:plane+vdb:nothing.vdb" \
  --light sun:azimuth=40,elevation=60 --resolution 64 -o none.pack
if "$st" inspect boxes.pack | grep -q "deep "; then echo "FAIL a scene without partial occluders has a deep part"; fail=1
else echo "ok   no deep part without partial occluders"; fi
light=sun:azimuth=40,elevation=60
from=(build "$hair" --resolution 128 --encoding mh --deep-tile 8 --tile-bytes 16384)
check export-deep 0 "exported deep level 6" -- "$st" export --deep "$hair" --light $light --level 6 --samples 2 -o hair.exr
check build-deep-from 0 "deep: from hair.exr, 64\^2 texels" -- "$st" "${from[@]}" --light $light --deep-from hair.exr -o hair_exr.pack
check verify-deep-from 0 "deep map: 256 texels sampled afresh" -- "$st" verify hair_exr.pack "$hair" --samples 2000
stored="$("$st" inspect hair.pack | grep -oE "[0-9]+ of 64 tiles")"
if [[ -n "$stored" && "$stored" == "$("$st" inspect hair_exr.pack | grep -oE "[0-9]+ of 64 tiles")" ]]
then echo "ok   deep-from stores the tiles sampling stores"; else echo "FAIL deep-from tile count differs"; fail=1; fi
check deep-from-light 1 "exported for light" -- "$st" "${from[@]}" --light sun:azimuth=41,elevation=60 --deep-from hair.exr -o x.pack
check deep-from-level 1 "its map is level 6, --deep-level says 5" -- "$st" "${from[@]}" --light $light --deep-level 5 --deep-from hair.exr -o x.pack
check export-part 0 "" -- "$st" export --deep "$hair" --light $light --level 6 --samples 2 --region 0,0,32,64 -o part.exr
check deep-from-part 1 "not the whole 64\^2 map" -- "$st" "${from[@]}" --light $light --deep-from part.exr -o x.pack
check export-flat 0 "" -- "$st" export boxes.pack --level 5 -o flat.exr
check deep-from-flat 1 "flat.exr: a flat \(not deep\) OpenEXR" -- "$st" "${from[@]}" --light $light --deep-from flat.exr -o x.pack
check deep-from-missing 1 "none.exr" -- "$st" "${from[@]}" --light $light --deep-from none.exr -o x.pack
exit $fail
