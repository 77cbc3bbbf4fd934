# Sourced by the CLI test scripts. check NAME EXPECTED_EXIT PATTERN -- command...: runs the
# command, prints "ok NAME" or "FAIL NAME" (with the output's tail) and sets fail=1 when
# the exit code differs or the output lacks the extended regex PATTERN ("" for any).
# same_pack A B [--ignore-params]: the packs hold the same header fields, params, skip
# grid and tile bytes (same_pack.py).
fail=0
check() {
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
same_pack() { python3 "$(dirname "${BASH_SOURCE[0]}")/same_pack.py" "$@"; }
