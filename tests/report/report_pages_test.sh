#!/usr/bin/env bash
# Every kind of HTML report page, made by the real commands on a small map and opened in
# headless Chromium (browser_check.py: sections, plots and images checked through the
# DOM, a screenshot of each page kept under WORKDIR/report_pages/screenshots/).
#   report_pages_test.sh PATH/TO/shadowtile SOURCE_DIR WORKDIR
# Exit 0 pass, 1 fail, 77 skipped (no matplotlib or no Chromium: scripts/deps installs both).
set -uo pipefail
st="$(realpath "$1")" src="$(realpath "$2")" work="$3/report_pages"
rm -rf "$work" && mkdir -p "$work/rep" && cd "$work"
py=python3; [ -x /usr/bin/python3 ] && py=/usr/bin/python3
"$py" -c "import matplotlib" 2>/dev/null || { echo "SKIP: no matplotlib for $py (scripts/deps installs python3-matplotlib)"; exit 77; }
command -v chromium >/dev/null || { echo "SKIP: no chromium on PATH (scripts/deps installs it)"; exit 77; }
scene="procedural:city,size=3" light="sun:azimuth=30,elevation=50"
fail=0
run() {  # run NAME EXIT PATTERN -- command...: exit EXIT (any: not checked), last line /PATTERN/
  local t0=$SECONDS
  local name="$1" want="$2" pattern="$3"; shift 4
  local out rc; out="$("$@" 2>&1)"; rc=$?
  if [[ "$want" != any && "$rc" != "$want" ]]; then
    echo "FAIL $name: exit $rc, expected $want"; echo "$out" | tail -8; fail=1; return
  fi
  if ! tail -n 1 <<<"$out" | grep -qE "$pattern"; then
    echo "FAIL $name: last line is not /$pattern/"; echo "$out" | tail -8; fail=1; return
  fi
  echo "ok   $name ($((SECONDS - t0)) s): $(tail -n 1 <<<"$out")"
}
run build 0 '^html: rep/build\.html$' -- "$st" build $scene --light $light --resolution 512 --encoding dagmh \
  --tile-bytes 8192 -o city.pack --report rep/build.json -q
run report 0 '^html: rep/quality/report\.html$' -- "$st" report --scene $scene --light $light --resolution 128 \
  --frames 1 --size 48x27 --encodings dagmh --pcf 3 --out rep/quality
# The soak runs the load tester too (its page lands in rep/soak/load/); a 1 s run may
# fail its memory rule: the page must say so, the verdict itself is not checked here. The
# load page needs 2 figures (timeline, latency); the per-cut one only once a cut completed.
run soak any '^html: .*rep/soak/soak\.html$' -- env SHADOWTILE_BIN="$st" "$src/scripts/soak" --no-build \
  --pack "$work/city.pack" --seconds 1 --cameras 2 --rate 30 --interval 0.25 --warmup 0 --out "$work/rep/soak"
run render 0 '^mean \|map - traced\| light over the receivers: ' -- "$st" render city.pack --scene $scene --camera "pos=-60,50,-70,target=0,0,0,fov=50" \
  --size 192x108 --diff -o rep/view.exr
run index 0 '^rep/index\.html$' -- "$py" "$src/scripts/html_report.py" index rep -o rep/index.html
# Bad input: exit 1 and one line naming the file and what is wrong, no page.
echo '{"series": 3' > rep/truncated.json
run bad-json 1 '^html_report.py: rep/truncated.json: not JSON' -- "$py" "$src/scripts/html_report.py" load \
  rep/truncated.json -o rep/bad.html
echo '{"error_vs_time": [{"map": "a", "error": 0.1, "ms_per_frame": 1}], "refinement": {"a": {"points": [[1]]}}}' \
  > rep/short_row.json
run bad-content 1 '^html_report.py: rep/short_row.json: unexpected content' -- "$py" "$src/scripts/html_report.py" \
  report rep/short_row.json -o rep/bad.html
[ ! -e rep/bad.html ] || { echo "FAIL bad input left a page"; fail=1; }
rm -f rep/truncated.json rep/short_row.json
[ "$fail" -eq 0 ] || exit 1
# A page the checks must refuse: an image that is not there, an empty plot, a fetch from
# the network, no #views section.
mkdir -p broken
cat > broken/broken.html <<'HTML'
<!DOCTYPE html><html><head><title>broken</title></head><body>
<section id="verdict"><h2>PASS</h2></section>
<figure id="fig1"><img src="missing.png" alt="x"></figure>
<figure id="fig2"><svg width="0" height="0"></svg></figure>
<figure id="fig3"><img src="http://127.0.0.1:9/x.png" alt="y"></figure>
</body></html>
HTML
"$py" "$src/tests/report/browser_check.py" --shots "$work/screenshots" \
  rep/build.html:verdict,stages,levels,tile_sizes,figures,provenance:3 \
  rep/quality/report.html:verdict,pareto,refinement,rows,provenance:3 \
  rep/soak/load/load.html:verdict,timeline,latency,cuts,figures,provenance:2 \
  rep/soak/soak.html:verdict,over_time,figures,provenance:3 \
  rep/index.html:verdict,views,provenance:3 \
  '!broken/broken.html:verdict,views:3'
