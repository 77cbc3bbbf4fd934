# Sourced by the examples' tests: lavapipe for Vulkan (skip, exit 77, without it), the city
# pack those tests stream (1024², 4 KiB tiles) built in $work and served on a free loopback
# port ($port; the server stops when the test exits). Needs $st (the shadowtile binary),
# $work (an empty folder) and fail().
server_pid=""
cleanup() { [[ -n "$server_pid" ]] && kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null; }
trap cleanup EXIT
export VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json XDG_RUNTIME_DIR="$work"
[[ -f "$VK_ICD_FILENAMES" ]] || { echo "SKIP: no lavapipe ($VK_ICD_FILENAMES)"; exit 77; }
scene="procedural:city,size=3"
"$st" build "$scene" --light sun:azimuth=120,elevation=30 --resolution 1024 --tile-bytes 4096 \
  -o "$work/city.pack" -q >/dev/null || fail "build"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$st" serve "$work/city.pack" --listen "127.0.0.1:$port" >"$work/serve.log" 2>&1 &
server_pid=$!
for _ in $(seq 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$work/serve.log"; fail "the server died"; }
  sleep 0.1
done
