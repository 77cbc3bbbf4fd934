# Sourced by the CLI test scripts. check NAME EXPECTED_EXIT PATTERN -- command...: runs the
# command, prints "ok NAME" or "FAIL NAME" (with the output's tail) and sets fail=1 when
# the exit code differs or the output lacks the extended regex PATTERN ("" for any); an
# "ok" line ends with the command's wall and CPU (user + sys) seconds: where a slow test
# spends its time.
# same_pack A B [--ignore-params]: the packs hold the same header fields, params, skip
# grid and tile bytes (same_pack.py).
# port_of LOG: waits up to 10 s for a server's banner ("... on 127.0.0.1:PORT") in LOG and
# prints PORT (nothing when it never came).
fail=0
# children_cpu_ms: sets cpu_ms to the CPU milliseconds (user + sys) of this shell's
# finished children so far: cutime + cstime of /proc/$$/stat, in clock ticks of 10 ms.
children_cpu_ms() {
  local f
  read -r -a f </proc/$$/stat
  cpu_ms=$(( (f[15] + f[16]) * 10 ))
}
check() {
  local name="$1" want="$2" pattern="$3"
  shift 4
  local out rc us cpu t0=${EPOCHREALTIME/./} c0
  children_cpu_ms
  c0=$cpu_ms
  out="$("$@" 2>&1)"
  rc=$?
  if [[ "$rc" != "$want" ]]; then
    echo "FAIL $name: exit $rc, expected $want"; echo "$out" | tail -5; fail=1; return
  fi
  if [[ -n "$pattern" ]] && ! grep -qE "$pattern" <<<"$out"; then
    echo "FAIL $name: output lacks /$pattern/"; echo "$out" | tail -5; fail=1; return
  fi
  us=$((${EPOCHREALTIME/./} - t0))
  children_cpu_ms
  cpu=$(( cpu_ms - c0 ))
  printf 'ok   %s (%d.%02d s, CPU %d.%02d s)\n' "$name" $((us / 1000000)) $((us / 10000 % 100)) \
    $((cpu / 1000)) $((cpu / 10 % 100))
}
same_pack() { python3 "$(dirname "${BASH_SOURCE[0]}")/same_pack.py" "$@"; }
port_of() {
  local p
  for _ in $(seq 1 500); do
    p=$(grep -oE "on 127\.0\.0\.1:[0-9]+" "$1" 2>/dev/null | head -1 | cut -d: -f2)
    [[ -n "$p" ]] && { echo "$p"; return; }
    sleep 0.02
  done
}
