#!/usr/bin/env bash
# Sharded builds as a batch system runs them: `build --shard I/N` parts joined by
# `merge` give the same pack as one build (header fields, skip grid, every tile's bytes),
# which verifies on every texel; merge refuses gaps, overlaps, parts of another build and
# corrupt or truncated parts, with one-line errors, leaving no output behind.
# Usage: shard_merge_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
st="$1"
work="$2/shard_merge_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
scene="procedural:city,size=3"
base=(build "$scene" --light sun:azimuth=30,elevation=50 --encoding dagmh)
args=("${base[@]}" --resolution 512 -q)
check one-go 0 "" -- "$st" "${args[@]}" -o one.pack
for i in 0 1 2; do check "part-$i" 0 "" -- "$st" "${args[@]}" --shard $i/3 -o p$i.part; done
check bad-shard 1 "shard: expected I/N" -- "$st" "${args[@]}" --shard 3/3 -o bad.part
check part-not-servable 1 "" -- "$st" inspect p0.part
check merge 0 "merged m.pack: 3 shards, 1024 cells" -- "$st" merge p2.part p0.part p1.part -o m.pack
if same_pack m.pack one.pack; then echo "ok   merged == one-go (header, params, skip grid, tile bytes)"
else echo "FAIL merged pack differs from the one-go build"; fail=1; fi
check verify-merged 0 "OK: every texel" -- "$st" verify m.pack "$scene" --all
check gap 1 "gap: no part holds shard 1/3" -- "$st" merge p0.part p2.part -o g.pack
check overlap 1 "overlap: p0.part and p0.part both hold shard 0/3" -- "$st" merge p0.part p0.part p1.part p2.part -o o.pack
check not-a-part 1 "one.pack: a complete pack, not a part file" -- "$st" merge one.pack p0.part -o n.pack
"$st" "${base[@]}" --resolution 1024 -q --shard 1/3 -o other.part >/dev/null 2>&1
check other-build 1 "different builds \(map level differs\)" -- "$st" merge p0.part other.part p2.part -o d.pack
# A flipped payload byte and a truncated part: refused, naming the part.
python3 - <<'PY'
d = bytearray(open("p1.part", "rb").read())
i = d.find(b"TREC")
assert i > 0
d[i + 40] ^= 0x20
open("p1-corrupt.part", "wb").write(d)
d = open("p1.part", "rb").read()
open("p1-short.part", "wb").write(d[:len(d) // 2])
PY
check corrupt-part 1 "p1-corrupt.part: record at byte [0-9]+ is torn or fails its CRC" -- "$st" merge p0.part p1-corrupt.part p2.part -o c.pack
check short-part 1 "p1-short.part: record at byte [0-9]+ is torn" -- "$st" merge p0.part p1-short.part p2.part -o s.pack
ls ./*.tmp g.pack o.pack n.pack d.pack c.pack s.pack >/dev/null 2>&1 && { echo "FAIL a refused merge left output behind"; fail=1; }
# A shard whose build was interrupted resumes into the same part.
cp p1-short.part p1r.part.tmp
check resume-shard 0 "[1-9][0-9]* resumed" -- "$st" "${base[@]}" --resolution 512 --shard 1/3 -o p1r.part --resume
check merge-resumed 0 "merged" -- "$st" merge p0.part p1r.part p2.part -o r.pack
if same_pack r.pack one.pack; then echo "ok   resumed shard merged == one-go"
else echo "FAIL resumed shard's merge differs from the one-go build"; fail=1; fi
exit $fail
