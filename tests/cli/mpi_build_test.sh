#!/usr/bin/env bash
# `build --mpi` under mpirun -np 2 on loopback: the pack equals a single-process build's
# (header, params, skip grid, every tile's bytes; so it verifies as that one does). A worker
# rank killed mid-way (SIGKILL, by pid) fails the run with a message naming it and no
# final pack; the same command with --resume completes the .tmp into the same pack.
# Usage: mpi_build_test.sh PATH/TO/shadowtile WORKDIR
set -uo pipefail
st="$1"
work="$2/mpi_build_test"
rm -rf "$work" && mkdir -p "$work" && cd "$work"
command -v mpirun >/dev/null || { echo "SKIP: mpirun is not installed (scripts/deps installs openmpi-bin)"; exit 0; }
"$st" build --help | grep -q -- "--mpi" || { echo "SKIP: this shadowtile was configured without MPI"; exit 0; }
mpi=(mpirun -np 2 --oversubscribe)
[[ $(id -u) == 0 ]] && mpi+=(--allow-run-as-root)
export OMPI_MCA_btl=self,vader,tcp OMPI_MCA_btl_tcp_if_include=lo OMPI_MCA_oob_tcp_if_include=lo
source "$(dirname "${BASH_SOURCE[0]}")/check.sh"
scene="procedural:city,size=3"
args=(build "$scene" --light sun:azimuth=30,elevation=50 --encoding dagmh)
"$st" "${args[@]}" --resolution 512 -q -o one.pack || exit 1
out=$("${mpi[@]}" "$st" "${args[@]}" --resolution 512 --mpi -o mpi.pack 2>&1)
if [[ $? == 0 ]] && grep -qE "mpi: 2 ranks built cells [0-9]+, [1-9][0-9]*" <<<"$out"; then
  echo "ok   mpirun -np 2 build: $(grep -o 'mpi: .*' <<<"$out")"
else echo "FAIL mpirun -np 2 build"; echo "$out" | tail -8; fail=1; fi
if [[ -f mpi.pack ]] && same_pack mpi.pack one.pack; then echo "ok   mpi pack == single-process pack"
else echo "FAIL mpi pack differs from the single-process build"; fail=1; fi

# Kill rank 1 once some cells are in the journal.
"$st" "${args[@]}" --resolution 2048 -q -o big_one.pack || exit 1
"${mpi[@]}" "$st" "${args[@]}" --resolution 2048 --mpi -o killed.pack >killed.log 2>&1 &
mp=$!
# The ranks are found first; then the journal is watched closely and both ranks are
# stopped (SIGSTOP) the moment it passes 8000 bytes, so the run cannot finish between
# that check and the kill (a plain kill raced the run's end); rank 1 is then killed and
# rank 0 continued.
rank0="" rank1=""
for _ in $(seq 1 1000); do
  for c in $(pgrep -P $mp 2>/dev/null); do
    env=$(tr '\0' '\n' <"/proc/$c/environ" 2>/dev/null)
    grep -qx "OMPI_COMM_WORLD_RANK=0" <<<"$env" && rank0=$c
    grep -qx "OMPI_COMM_WORLD_RANK=1" <<<"$env" && rank1=$c
  done
  [[ -n "$rank0" && -n "$rank1" ]] && break
  kill -0 $mp 2>/dev/null || break
  sleep 0.01
done
for _ in $(seq 1 20000); do
  [[ -z "$rank1" ]] && break
  if [[ -f killed.pack.tmp ]] && (( $(stat -c %s killed.pack.tmp 2>/dev/null || echo 0) > 8000 )); then
    kill -STOP "$rank0" "$rank1" 2>/dev/null
    break
  fi
  kill -0 $mp 2>/dev/null || break
  sleep 0.002
done
if [[ -z "$rank1" || -f killed.pack ]] || ! kill -0 $mp 2>/dev/null; then
  echo "FAIL kill-rank: ranks not found or the run ended before it could be killed"; fail=1
  kill -CONT "$rank0" "$rank1" 2>/dev/null
  kill $mp 2>/dev/null; wait $mp 2>/dev/null
else
  kill -9 "$rank1"
  kill -CONT "$rank0"
  for _ in $(seq 1 300); do kill -0 $mp 2>/dev/null || break; sleep 0.1; done
  kill $mp 2>/dev/null
  wait $mp; rc=$?
  if [[ $rc != 0 && ! -f killed.pack && -f killed.pack.tmp ]] && grep -qiE "rank 1|signal 9|killed" killed.log; then
    echo "ok   killed rank 1: run failed (exit $rc), no pack, .tmp kept: $(grep -iE 'rank 1|signal 9' killed.log | head -1)"
  else echo "FAIL killed rank: exit $rc, pack $(ls killed.pack 2>&1)"; tail -n 5 killed.log; fail=1; fi
  out=$("${mpi[@]}" "$st" "${args[@]}" --resolution 2048 --mpi --resume -o killed.pack 2>&1)
  if [[ $? == 0 ]] && grep -qE "[1-9][0-9]* resumed" <<<"$out" && same_pack killed.pack big_one.pack; then
    echo "ok   --mpi --resume completed the pack == single-process pack"
  else echo "FAIL --mpi --resume"; echo "$out" | tail -5; fail=1; fi
fi
exit $fail
