#!/usr/bin/env bash
# Replicated serving on loopback: two shadowtile-server replicas of one pack behind
# HAProxy (deploy/haproxy.cfg, whose health check speaks the protocol), one load run
# through HAProxy and one with both replicas as direct endpoints (--server A,B). One
# replica is killed (SIGKILL) in the middle: both runs end with zero errors (every tile
# passing its end-to-end CRC, none given up, no failed connect), the direct run failed
# over (a disconnect), and HAProxy's check marks the dead replica DOWN. Every process the
# test starts is stopped by pid. Usage: replicas_test.sh shadowtile shadowtile-server DEPLOY_DIR WORKDIR
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
st="$1" srv="$2" deploy="$3"
work="$4/replicas_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
command -v haproxy >/dev/null || { echo "SKIP: haproxy is not installed (scripts/deps installs it)"; exit 0; }
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done; }
trap cleanup EXIT
die() { echo "FAIL $*"; exit 1; }
"$st" build procedural:city,size=3 --light sun:azimuth=30,elevation=50 --resolution 512 -o city.pack -q || die build
"$srv" city.pack --listen 127.0.0.1:0 2>s1.log & s1=$!; pids+=($s1)
"$srv" city.pack --listen 127.0.0.1:0 2>s2.log & s2=$!; pids+=($s2)
p1=$(port_of s1.log); p2=$(port_of s2.log)
[[ -n "$p1" && -n "$p2" ]] || die "replicas did not start: $(cat s1.log s2.log)"
front=$(python3 -c "import socket; s=socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])")
sed -e "s/127\.0\.0\.1:7440/127.0.0.1:$front/" -e "s/127\.0\.0\.1:7447/127.0.0.1:$p1/" \
    -e "s/127\.0\.0\.1:7448/127.0.0.1:$p2/" "$deploy/haproxy.cfg" > haproxy.cfg
grep -q "127.0.0.1:$p2 check" haproxy.cfg || die "could not write haproxy.cfg from the template"
haproxy -f haproxy.cfg -db 2>haproxy.log & hp=$!; pids+=($hp)
sleep 1.2  # the first health checks (inter 1s) pass
kill -0 $hp 2>/dev/null || die "haproxy did not start: $(cat haproxy.log)"
grep -q "is DOWN" haproxy.log && die "a healthy replica was marked down: $(grep DOWN haproxy.log)"
# 8 s: the kill below lands once the direct run holds a connection to replica 1, which on
# a loaded 2-core machine (GPU tests compiling beside it) came late enough in a 3 s run
# that the run had ended before the kill, so nothing failed over.
load=(load --map city --cameras 2 --duration 8 --rate 30)
"$st" "${load[@]}" --server 127.0.0.1:$front --report via_haproxy >via_haproxy.log 2>&1 & la=$!; pids+=($la)
"$st" "${load[@]}" --server 127.0.0.1:$p1,127.0.0.1:$p2 --report direct >direct.log 2>&1 & lb=$!; pids+=($lb)
# Kill replica 1 once the direct run holds a connection to it (a fixed sleep raced a
# slow start under the sanitizers or a loaded machine: the run then met a dead replica at
# its first connect, a failed connect, and never failed over). The run's sockets are the
# inodes behind its fds; /proc/net/tcp names each one's peer port and state (01: open).
connected_to() {  # connected_to PID PORT: PID has an established TCP connection to PORT
  python3 - "$1" "$2" <<'PY'
import os, sys
pid, port = sys.argv[1], int(sys.argv[2])
try:
    inodes = {os.readlink(f"/proc/{pid}/fd/{f}")[8:-1] for f in os.listdir(f"/proc/{pid}/fd")}
except OSError:
    sys.exit(1)
for line in open("/proc/net/tcp").readlines()[1:]:
    f = line.split()
    if int(f[2].split(":")[1], 16) == port and f[3] == "01" and f[9] in inodes:
        sys.exit(0)
sys.exit(1)
PY
}
for _ in $(seq 1 200); do connected_to $lb $p1 && break; sleep 0.05; done
connected_to $lb $p1 || die "the direct run did not connect to replica 1 within 10 s: $(tail -n 3 direct.log)"
sleep 0.3  # a few frames' requests in flight on it
kill -0 $lb 2>/dev/null || die "the direct run ended before replica 1 was killed: $(tail -n 3 direct.log)"
kill -9 $s1; wait $s1 2>/dev/null
wait $la; ra=$?
wait $lb; rb=$?
fail=0
python3 - <<'PY' || fail=1
import json, sys
ok = True
for name in ("via_haproxy", "direct"):
    r = json.load(open(name + "/load.json"))
    e, t = r["errors"], r["tiles"]
    if e["total"] or t["failed"] or t["received"] == 0:
        print(f"FAIL {name}: errors {e}, tiles {t['received']} received, {t['failed']} failed"); ok = False
    else:
        print(f"ok   {name}: {t['received']} tiles received, 0 errors, connections {r['connections']}")
if json.load(open("direct/load.json"))["connections"]["disconnects"] < 1:
    print("FAIL direct: no client was connected to the killed replica (no failover exercised)"); ok = False
sys.exit(0 if ok else 1)
PY
[[ $ra == 0 && $rb == 0 ]] || { echo "FAIL load exit codes: via haproxy $ra, direct $rb"; tail -n 3 via_haproxy.log direct.log; fail=1; }
for _ in $(seq 1 40); do grep -q "replica1 is DOWN" haproxy.log && break; sleep 0.1; done
if grep -q "replica1 is DOWN" haproxy.log && ! grep -q "replica2 is DOWN" haproxy.log; then
  echo "ok   haproxy marked the killed replica down: $(grep -o 'replica1 is DOWN[^.]*' haproxy.log | head -1)"
else echo "FAIL haproxy log lacks 'replica1 is DOWN' (or marked replica2 down)"; cat haproxy.log; fail=1; fi
exit $fail
