#!/usr/bin/env bash
# The demo's day (scripts/demo-day, scripts/day_report.py) on a tiny stack: every figure in
# day.json is the one the commands wrote (pack sizes on disk, the renders' differing
# receivers, the load run's frames and slice crossings), and bad input is one line.
#   day_report_test.sh PATH/TO/shadowtile SOURCE_DIR WORKDIR
set -uo pipefail
st="$(realpath "$1")" src="$(realpath "$2")" work="$3/day_report"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
fail() { echo "FAIL: $*"; exit 1; }
export SHADOWTILE_DAY_SCENE="procedural:city,size=2" SHADOWTILE_DAY_RES=128 SHADOWTILE_DAY_SIZE=96x54
export SHADOWTILE_DAY_LIGHT="sun-path:azimuth=150..200,elevation=40..60,samples=4"
export SHADOWTILE_DAY_CAMERA="pos=-60,50,-70,target=0,0,0,fov=50" SHADOWTILE_DAY_TIMES="0.5 1"
export SHADOWTILE_DAY_LOAD_SECONDS=1 SHADOWTILE_DAY_GPU=0 SHADOWTILE_DAY_FINE=1
export SHADOWTILE_HTML=0  # load's own page: report.pages_in_chromium tests those
"$src/scripts/demo-day" build "$st" out day >build.log 2>&1 || { tail -5 build.log; fail "demo-day build"; }
[ "$(awk -F'\t' '$1 == "2d"' day/builds.tsv | wc -l)" = 4 ] || fail "expected 4 2D packs in builds.tsv"
[ "$(awk -F'\t' '$1 == "2d_fine"' day/builds.tsv | wc -l)" = 4 ] || fail "expected 4 2D packs at 256^2 in builds.tsv"
[ "$(awk -F'\t' '$1 == "stack1"' day/builds.tsv | wc -l)" = 4 ] || fail "expected 4 one-sample stacks in builds.tsv"

port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$st" serve out/day.pack --listen "127.0.0.1:$port" >serve.log 2>&1 &
serve_pid=$!
trap 'kill "$serve_pid" 2>/dev/null; wait "$serve_pid" 2>/dev/null' EXIT
for _ in $(seq 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
  sleep 0.05
done
"$src/scripts/demo-day" stream "$st" "$port" day >stream.log 2>&1 || { tail -5 stream.log; fail "demo-day stream"; }

# day.json against the sources it was gathered from.
python3 - "$work" "$st" <<'PY' || exit 1
import json, math, os, re, subprocess, sys
d = os.path.join(sys.argv[1], "day")
j = json.load(open(os.path.join(d, "day.json")))
def check(ok, what):
    if not ok:
        sys.exit("FAIL: " + what)
check(j["stack"]["bytes"] == os.path.getsize(os.path.join(sys.argv[1], "out", "day.pack")), "stack bytes = the pack's size")
sizes = [os.path.getsize(os.path.join(sys.argv[1], "out", "day2d", "s%d.pack" % w)) for w in range(4)]
check(j["packs_2d"]["count"] == 4 and j["packs_2d"]["bytes"] == sum(sizes), "2D bytes = the packs' sizes")
check(abs(j["stack_over_2d_bytes"] - j["stack"]["bytes"] / sum(sizes)) < 1e-12, "the bytes ratio")
fine = [os.path.getsize(os.path.join(sys.argv[1], "out", "day2d_fine", "s%d.pack" % w)) for w in range(4)]
check(j["packs_2d_fine"]["count"] == 4 and j["packs_2d_fine"]["bytes"] == sum(fine), "2D bytes at 256^2 = the packs' sizes")
check(abs(j["stack_over_2d_fine_bytes"] - j["stack"]["bytes"] / sum(fine)) < 1e-12, "the bytes ratio at 256^2")
one = [os.path.getsize(os.path.join(sys.argv[1], "out", "day1", "s%d.pack" % w)) for w in range(4)]
check(j["packs_stack1"]["count"] == 4 and j["packs_stack1"]["bytes"] == sum(one), "one-sample stacks' bytes = the packs' sizes")
check(abs(j["stack_over_stack1_bytes"] - j["stack"]["bytes"] / sum(one)) < 1e-12, "the bytes ratio to one-sample stacks")
# Ground area per texel from each pack's light box: the ground frame's square over 128^2
# in every slice; a sun's side over 128 (256) squared, stretched by 1 / sin(elevation).
def texel_area(path, res):
    t = json.loads(subprocess.run([sys.argv[2], "inspect", "--json", path], capture_output=True, check=True).stdout)["light_transform"]
    e = t["extent"] / res
    return e * e if t["kind"] == "sun-ground" else e * e / math.sin(math.radians(t["array"][16]))
check(abs(j["stack"]["texel_ground_area"] / texel_area(os.path.join(sys.argv[1], "out", "day.pack"), 128) - 1) < 1e-9, "the stack's texel area")
for w, p in enumerate(j["packs_2d"]["each"] + j["packs_2d_fine"]["each"] + j["packs_stack1"]["each"]):
    res, folder = [(128, "day2d"), (256, "day2d_fine"), (128, "day1")][w // 4]
    a = texel_area(os.path.join(sys.argv[1], "out", folder, "s%d.pack" % (w % 4)), res)
    check(abs(p["texel_ground_area"] / a - 1) < 1e-9, "pack %d's texel area" % w)
    if w >= 8:  # one sun's ground square: inside the union of every sun's, so no coarser
        check(p["texel_ground_area"] <= j["stack"]["texel_ground_area"], "one-sample stack %d no coarser" % (w - 8))
    elif w >= 4:  # the same sun's box at twice the resolution: a quarter of the area
        check(abs(p["texel_ground_area"] * 4 / j["packs_2d"]["each"][w - 4]["texel_ground_area"] - 1) < 1e-9, "pack %d at 256^2" % w)
check(j["stack"]["build_s"] > 0 and j["packs_2d"]["build_s"] > 0 and all(p["seconds"] > 0 for p in j["packs_2d"]["each"]), "build times measured")
# The 2D packs' suns are the stack's samples (azimuth, elevation linear in w / 3).
for w, p in enumerate(j["packs_2d"]["each"]):
    check(abs(p["azimuth"] - (150 + 50 * w / 3)) < 1e-9 and abs(p["elevation"] - (40 + 20 * w / 3)) < 1e-9, "sample %d" % w)
check([r["time"] for r in j["renders"]] == [0.5, 1.0], "render times")
for r in j["renders"]:
    text = open(os.path.join(d, "render_%g.txt" % r["time"])).read()
    m = re.search(r"differing pixels: (\d+) of (\d+)", text)
    check((r["differing"], r["receivers"]) == (int(m.group(1)), int(m.group(2))), "render %g counts" % r["time"])
    check(os.path.exists(os.path.join(d, r["traced"])), "the ray-traced view beside it")
check(j["renders"][0]["slices"].endswith("slices 1 and 2 blended"), "time 0.5 of 4 samples blends slices 1 and 2")
lj = json.load(open(os.path.join(d, "load", "load.json")))
L = j["load"]
check(L["frames"] == lj["frames"]["total"] == lj["frame_ms"]["frames"], "load frames")
check(L["errors"] == 0 and L["slices"] == 4, "load: no errors, 4 slices")
# One camera sweeping 0..1 over 60 frames (the last before time 1) enters slices 1, 2, 3
# once each: 3 crossings, whatever the machine's speed.
check(lj["frames"]["total"] == 60 and L["crossings"]["frames"] == 3, "3 slice crossings in 60 frames: %s" % L["crossings"])
check(0 < L["frame_ms"]["p50"] <= L["frame_ms"]["max"] and L["crossings"]["max_ms"] <= L["frame_ms"]["max"], "frame times")
check(j["gpu"] is None, "no GPU view asked for")
txt = open(os.path.join(d, "day.txt")).read()
check("stack / 2D = %.3f" % j["stack_over_2d_bytes"] in txt, "day.txt carries the ratio")
check("stack / 2D at 256^2 = %.3f" % j["stack_over_2d_fine_bytes"] in txt, "day.txt carries the ratio at 256^2")
check("stack / those = %.3f" % j["stack_over_stack1_bytes"] in txt, "day.txt carries the ratio to one-sample stacks")
print("ok   day.json: stack %d B, 2D %d B, %d frames, %d crossings" % (j["stack"]["bytes"], sum(sizes), L["frames"],
                                                                       L["crossings"]["frames"]))
PY

# The index page shows the day (where matplotlib is installed).
py=python3; [ -x /usr/bin/python3 ] && py=/usr/bin/python3
if "$py" -c "import matplotlib" 2>/dev/null; then
  "$py" "$src/scripts/html_report.py" index . -o index.html >/dev/null || fail "html_report.py index"
  grep -q '<section id="day"' index.html || fail "index.html has no day section"
  grep -q 'day/render_0.5_traced.png' index.html || fail "index.html does not show the ray-traced view"
  echo "ok   index.html: day section"
fi

# Bad input: one line naming the file, exit 1.
cp day/builds.tsv builds.keep
sed -i '0,/^2d\t/s/^\(2d\t[^\t]*\t\)[0-9]*/\11/' day/builds.tsv
out="$(python3 "$src/scripts/day_report.py" day 2>&1)"; rc=$?
[[ $rc == 1 && $(wc -l <<<"$out") == 1 && "$out" == *"builds.tsv:"*"holds"*"bytes, not 1"* ]] ||
  fail "a wrong size in builds.tsv: exit $rc, '$out'"
cp builds.keep day/builds.tsv
sed -i '/^differing pixels/d' day/render_1.txt
out="$(python3 "$src/scripts/day_report.py" day 2>&1)"; rc=$?
[[ $rc == 1 && "$out" == "day_report.py: day/render_1.txt: no 'differing pixels' line" ]] ||
  fail "a render without its count: exit $rc, '$out'"
echo "ok   bad input named in one line"
