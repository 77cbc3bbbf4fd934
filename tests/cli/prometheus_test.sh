#!/usr/bin/env bash
# `shadowtile stats --prometheus FILE` against a loopback server under load: the file
# parses with Prometheus' own parser (Debian's python3-prometheus-client), its names and
# types follow the naming rules, and every value equals the GetStats answer of the same
# sample (the --jsonl line). With the server gone the file says shadowtile_server_up 0.
# Usage: prometheus_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
st="$1"
work="$2/prometheus_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
py=/usr/bin/python3
if ! "$py" -c "import prometheus_client" 2>/dev/null; then
  echo "SKIP: python3-prometheus-client is not installed (scripts/deps installs it)"; exit 0
fi
"$st" build procedural:city,size=3 --light sun:azimuth=30,elevation=50 --resolution 512 -o city.pack -q || exit 1
"$st" serve city.pack --listen 127.0.0.1:0 2>serve.log &
spid=$!
trap 'kill $spid 2>/dev/null; wait $spid 2>/dev/null' EXIT
port=$(port_of serve.log)
[[ -n "$port" ]] || { echo "FAIL: no port in serve.log"; cat serve.log; exit 1; }
"$st" load --server 127.0.0.1:$port --map city --cameras 2 --duration 1 --rate 30 >load.log 2>&1 \
  || { echo "FAIL: load run"; tail -5 load.log; exit 1; }
"$st" stats --server 127.0.0.1:$port --interval 0.25 --duration 1 --prometheus city.prom --jsonl stats.jsonl \
  >stats.log 2>&1 || { echo "FAIL: stats"; tail -5 stats.log; exit 1; }
ls city.prom.*.tmp >/dev/null 2>&1 && { echo "FAIL: a temporary textfile was left"; exit 1; }
"$py" - 127.0.0.1:$port <<'PY' || exit 1
import json, math, re, sys
from prometheus_client.parser import text_string_to_metric_families
server = sys.argv[1]
text = open("city.prom").read()
fams = {f.name: f for f in text_string_to_metric_families(text)}
last = [json.loads(l) for l in open("stats.jsonl")][-1]
counters, latency = last["counters"], last["latency_us"]
ok = True
def fail(msg):
    global ok
    print("FAIL " + msg); ok = False
for name, f in fams.items():
    if not re.fullmatch(r"shadowtile_server_[a-z_]+", name): fail(f"metric name {name}")
    for s in f.samples:
        if s.labels.get("server") != server: fail(f"{s.name} lacks server=\"{server}\"")
        if f.type == "counter" and not s.name.endswith("_total"): fail(f"counter sample {s.name} lacks _total")
def value(family, sample=None):
    f = fams[family]
    return [s.value for s in f.samples if s.name == (sample or family)][0]
if value("shadowtile_server_up") != 1: fail("up is not 1")
expect = {"connections_total": ("shadowtile_server_connections", "counter"),
          "connections_open": ("shadowtile_server_connections_open", "gauge"),
          "requests": ("shadowtile_server_requests", "counter"),
          "tiles_sent": ("shadowtile_server_tiles_sent", "counter"),
          "tile_bytes_sent": ("shadowtile_server_tile_sent_bytes", "counter"),
          "bytes_sent": ("shadowtile_server_sent_bytes", "counter"),
          "bytes_received": ("shadowtile_server_received_bytes", "counter"),
          "errors": ("shadowtile_server_error_frames", "counter"),
          "protocol_errors": ("shadowtile_server_protocol_errors", "counter"),
          "timeouts": ("shadowtile_server_timeouts", "counter")}
for c, (fam, typ) in expect.items():
    if fams[fam].type != typ: fail(f"{fam} has type {fams[fam].type}, want {typ}")
    got = value(fam, fam + "_total" if typ == "counter" else fam)
    if got != counters[c]: fail(f"{fam} = {got}, GetStats {c} = {counters[c]}")
if counters["tiles_sent"] == 0: fail("the load run sent no tiles")
h = fams["shadowtile_server_tile_latency_seconds"]
if h.type != "histogram": fail("latency is not a histogram")
buckets = [(s.labels["le"], s.value) for s in h.samples if s.name.endswith("_bucket")]
cum, want = 0, []
for b, c in enumerate(latency):
    cum += c
    want.append(("+Inf" if b == len(latency) - 1 else repr(float((2 ** b - 1) / 1e6)), cum))
got = [(le if le == "+Inf" else repr(float(le)), v) for le, v in buckets]
if got != want: fail(f"buckets {got[:6]}... differ from GetStats' {want[:6]}...")
count = value("shadowtile_server_tile_latency_seconds", "shadowtile_server_tile_latency_seconds_count")
total = value("shadowtile_server_tile_latency_seconds", "shadowtile_server_tile_latency_seconds_sum")
if count != sum(latency) or count == 0: fail(f"_count {count} != {sum(latency)}")
if not math.isclose(total, counters["latency_sum_us"] / 1e6, rel_tol=1e-12): fail(f"_sum {total}")
print("ok   prometheus textfile == GetStats (%d families, %d tiles, %d latency samples)"
      % (len(fams), counters["tiles_sent"], count))
sys.exit(0 if ok else 1)
PY
kill $spid; wait $spid 2>/dev/null
"$st" stats --server 127.0.0.1:$port --interval 0.2 --duration 0.3 --prometheus city.prom >/dev/null 2>&1
if "$py" -c "
from prometheus_client.parser import text_string_to_metric_families as p
f = {x.name: x for x in p(open('city.prom').read())}
assert list(f) == ['shadowtile_server_up'] and f['shadowtile_server_up'].samples[0].value == 0
"; then echo "ok   server gone: shadowtile_server_up 0"
else echo "FAIL server gone: file does not say up 0"; cat city.prom; exit 1; fi
