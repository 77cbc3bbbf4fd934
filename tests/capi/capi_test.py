#!/usr/bin/env python3
"""The C API (shadowtile.h) end to end, standard library only.

  capi_test.py exports LIBSHADOWTILE
      libshadowtile.so has a SONAME and exports only the C API (shadowtile_*) and the C++
      API (st::client::...): nothing of common, proto, tiles_core, Asio or the standard
      library's instantiations.

  capi_test.py serve SHADOWTILE SERVER PACK_PROBE LIBSHADOWTILE C_CLIENT MINIMAL TMP
      Builds a small pack, serves it on loopback, and answers one batch of world points
      four ways: the pack read locally (pack_probe, the reference), the C example
      (examples/c_client.c), the C++ example (examples/minimal.cpp) and a Python ctypes
      binding of libshadowtile.so written here. All four must agree bit for bit. Then the
      binding checks the error model: status codes, the thread-local message, the
      callback, and a map that outlives its client.
"""
import ctypes as C
import os
import re
import shutil
import socket
import subprocess
import sys
import threading
import time


def fail(msg):
    print("FAIL capi: " + msg)
    sys.exit(1)


# ---------------------------------------------------------------- the binding

OK, INVALID_ARGUMENT, NOT_FOUND, TIMEOUT, REFUSED = 0, 1, 2, 3, 4


class Endpoint(C.Structure):
    _fields_ = [("host", C.c_char_p), ("port", C.c_uint16)]


class ClientOptions(C.Structure):
    _fields_ = [("cache_slots", C.c_uint32), ("max_slot_bytes", C.c_uint32), ("want_capacity", C.c_uint32),
                ("max_frame_bytes", C.c_uint32), ("max_tile_retries", C.c_uint32),
                ("max_in_flight", C.c_uint16), ("tiles_per_request", C.c_uint16), ("miss_priority", C.c_uint16),
                ("reserved", C.c_uint16),
                ("connect_timeout_ms", C.c_uint32), ("io_timeout_ms", C.c_uint32), ("request_timeout_ms", C.c_uint32),
                ("backoff_initial_ms", C.c_uint32), ("backoff_max_ms", C.c_uint32),
                ("client_name", C.c_char_p), ("key", C.POINTER(C.c_uint8)), ("key_size", C.c_size_t),
                ("tls", C.c_int32), ("tls_ca_file", C.c_char_p), ("tls_server_name", C.c_char_p)]


class MapListing(C.Structure):
    _fields_ = [("name", C.c_char_p), ("encoding", C.c_char_p), ("resolution_log2", C.c_uint32),
                ("skip_level", C.c_uint32), ("tile_count", C.c_uint32), ("reserved", C.c_uint32),
                ("pack_bytes", C.c_uint64)]


class MapInfo(C.Structure):
    _fields_ = [("name", C.c_char_p), ("encoding", C.c_char_p), ("finest_level", C.c_uint32),
                ("skip_level", C.c_uint32), ("tile_bytes", C.c_uint32), ("slices", C.c_uint32),
                ("tile_count", C.c_uint64), ("scene_hash", C.c_uint64), ("sun", C.c_int32), ("has_deep", C.c_int32)]


class Point(C.Structure):
    _fields_ = [("x", C.c_double), ("y", C.c_double), ("z", C.c_double)]


class Rgb(C.Structure):
    _fields_ = [("r", C.c_float), ("g", C.c_float), ("b", C.c_float)]


class ClientStats(C.Structure):
    _fields_ = [(n, C.c_uint64) for n in ("connects", "connect_failures", "disconnects", "frames_received",
                                          "bytes_received", "bytes_sent", "protocol_errors")] + \
               [("connected", C.c_int32), ("refused", C.c_int32)]


class MapStats(C.Structure):
    _fields_ = [(n, C.c_uint64) for n in ("cache_hits", "cache_misses", "cache_evictions", "cache_inserts")] + \
               [(n, C.c_uint32) for n in ("slots_resident", "slots_pinned", "slots_free", "reserved")] + \
               [(n, C.c_uint64) for n in ("tiles_requested", "tiles_received", "bytes_received", "crc_errors",
                                          "decode_errors", "tiles_failed", "tiles_cancelled", "cache_full",
                                          "queue_full", "coarse_answers", "dictionary_bytes")]


ErrorCallback = C.CFUNCTYPE(None, C.c_void_p, C.c_int, C.c_char_p)


def load(path):
    lib = C.CDLL(path)
    P = C.POINTER
    sig = {
        "shadowtile_version": (C.c_char_p, []),
        "shadowtile_c_api_version": (C.c_uint32, []),
        "shadowtile_status_name": (C.c_char_p, [C.c_int]),
        "shadowtile_last_error": (C.c_char_p, []),
        "shadowtile_set_error_callback": (None, [ErrorCallback, C.c_void_p]),
        "shadowtile_client_options_default": (None, [P(ClientOptions)]),
        "shadowtile_client_create": (C.c_int, [P(Endpoint), C.c_size_t, P(ClientOptions), P(C.c_void_p)]),
        "shadowtile_client_destroy": (None, [C.c_void_p]),
        "shadowtile_client_get_stats": (C.c_int, [C.c_void_p, P(ClientStats)]),
        "shadowtile_client_list_maps": (C.c_int, [C.c_void_p, P(P(MapListing)), P(C.c_size_t)]),
        "shadowtile_free_map_listings": (None, [P(MapListing)]),
        "shadowtile_client_open_map": (C.c_int, [C.c_void_p, C.c_char_p, P(C.c_void_p)]),
        "shadowtile_map_close": (None, [C.c_void_p]),
        "shadowtile_map_get_info": (C.c_int, [C.c_void_p, P(MapInfo)]),
        "shadowtile_map_visibility": (C.c_int, [C.c_void_p, P(Point), C.c_size_t, C.c_uint32, P(C.c_float)]),
        "shadowtile_map_visibility_filtered": (C.c_int, [C.c_void_p, P(Point), P(C.c_float), C.c_size_t,
                                                         C.c_uint32, P(C.c_float)]),
        "shadowtile_map_transmittance": (C.c_int, [C.c_void_p, P(Point), P(C.c_float), C.c_size_t, P(Rgb)]),
        "shadowtile_map_request_region": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                    C.c_uint64, C.c_uint16, P(C.c_size_t)]),
        "shadowtile_map_cancel_outside": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                    C.c_uint64, P(C.c_size_t)]),
        "shadowtile_map_region_resident": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                     C.c_uint64, P(C.c_int32)]),
        "shadowtile_map_get_stats": (C.c_int, [C.c_void_p, P(MapStats)]),
    }
    for name, (res, args) in sig.items():
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def expect(status, want, what, lib):
    if status != want:
        fail("%s: status %d (%s), expected %d: %s" % (what, status, lib.shadowtile_status_name(status).decode(),
                                                     want, lib.shadowtile_last_error().decode()))


def bits(f):
    return "%08x" % C.c_uint32.from_buffer(C.c_float(f)).value


# ---------------------------------------------------------------- exports


def check_exports(lib_path):
    dyn = subprocess.run(["readelf", "-d", lib_path], capture_output=True, text=True, check=True).stdout
    m = re.search(r"\(SONAME\)\s+Library soname: \[(libshadowtile\.so\.[0-9.]+)\]", dyn)
    if not m:
        fail("no SONAME libshadowtile.so.N in %s:\n%s" % (lib_path, dyn))
    nm = subprocess.run(["nm", "-D", "--defined-only", "-C", lib_path], capture_output=True, text=True,
                        check=True).stdout
    c_api, cpp_api, other = [], [], []
    for line in nm.splitlines():
        parts = line.split(" ", 2)
        if len(parts) < 3:
            continue
        sym = parts[2]
        if re.fullmatch(r"shadowtile_[a-z_]+", sym):
            c_api.append(sym)
        elif sym.startswith("st::client::"):
            cpp_api.append(sym)
        else:
            other.append(sym)
    if other:
        fail("libshadowtile.so exports %d symbols outside the API, e.g.:\n  %s" % (len(other), "\n  ".join(other[:10])))
    internal = [s for s in cpp_api if re.match(r"st::client::(RemoteMap|Fetcher|IoPool|MapAccess|TileRequests|"
                                               r"DeepPart)\b", s)]
    if internal:
        fail("internal classes exported: %s" % internal[:5])
    want_c = {"shadowtile_client_create", "shadowtile_map_visibility", "shadowtile_last_error"}
    want_cpp = ("st::client::Client::open", "st::client::Map::visibility", "st::client::make_io_pool")
    if not want_c <= set(c_api) or not all(any(s.startswith(w) for s in cpp_api) for w in want_cpp):
        fail("API symbols missing: C %s, C++ %d symbols" % (sorted(c_api), len(cpp_api)))
    print("capi: %s exports %d C and %d C++ symbols, nothing else" % (m.group(1), len(c_api), len(cpp_api)))


# ---------------------------------------------------------------- serve


def run(cmd, stdin=None, what=None):
    r = subprocess.run(cmd, input=stdin, capture_output=True, text=True, timeout=120)
    if r.returncode != 0:
        fail("%s exited %d:\n%s" % (what or cmd[0], r.returncode, r.stderr[-2000:]))
    return r.stdout


def first_column(text):
    return [line.split()[0] for line in text.splitlines()]


def check_serve(st, server, probe, lib_path, c_client, minimal, tmp):
    work = os.path.join(tmp, "capi.%d" % os.getpid())
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    pack = os.path.join(work, "city.pack")
    run([st, "build", "procedural:city", "--light", "sun:azimuth=30,elevation=50", "--resolution", "256",
         "--encoding", "dagmh", "--tile-bytes", "2048", "-o", pack, "-q"], what="shadowtile build")
    points_text = run([probe, pack, "points", "3000", "7"], what="pack_probe points")
    want = first_column(run([probe, pack, "visibility"], stdin=points_text, what="pack_probe visibility"))
    points = [tuple(float(v) for v in line.split()) for line in points_text.splitlines()]
    if len(want) != len(points) or len(points) != 3000:
        fail("reference has %d answers for %d points" % (len(want), len(points)))
    lit = sum(1 for b in want if b == "3f800000")
    if not (0 < lit < len(want)):
        fail("the points are all lit or all shadowed (%d of %d lit): a weak test" % (lit, len(want)))

    log = open(os.path.join(work, "serve.log"), "w+")
    srv = subprocess.Popen([server, pack, "--listen", "127.0.0.1:0"], stderr=log, stdout=subprocess.DEVNULL)
    try:
        port = None
        for _ in range(100):
            log.seek(0)
            m = re.search(r"on 127\.0\.0\.1:([0-9]+)", log.read())
            if m:
                port = int(m.group(1))
                break
            time.sleep(0.1)
        if port is None:
            log.seek(0)
            fail("no port in the server's banner:\n" + log.read())
        # The examples: C99 over the C API, C++20 over client.hpp.
        got_c = first_column(run([c_client, "127.0.0.1", str(port), "city", "128"], stdin=points_text))
        got_cpp = first_column(run([minimal, "127.0.0.1", str(port), "city", "128"], stdin=points_text))
        for name, got in (("examples/c_client", got_c), ("examples/minimal", got_cpp)):
            if got != want:
                diff = [i for i in range(min(len(got), len(want))) if got[i] != want[i]]
                fail("%s: %d answers, %d differ from the pack's (first at %s)" % (name, len(got), len(diff), diff[:3]))
        check_binding(lib_path, port, points, want, got_c)
    finally:
        srv.terminate()
        srv.wait(timeout=10)
        log.close()
    shutil.rmtree(work, ignore_errors=True)


def check_binding(lib_path, port, points, want, got_c):
    lib = load(lib_path)
    version = lib.shadowtile_version().decode()
    if not re.fullmatch(r"[0-9]+\.[0-9]+\.[0-9]+", version) or lib.shadowtile_c_api_version() < 1:
        fail("version %r, C API version %d" % (version, lib.shadowtile_c_api_version()))
    errors = []
    callback = ErrorCallback(lambda user, status, message: errors.append((status, message.decode())))
    lib.shadowtile_set_error_callback(callback, None)

    options = ClientOptions()
    lib.shadowtile_client_options_default(C.byref(options))
    if (options.cache_slots, options.request_timeout_ms, options.max_in_flight) != (256, 10000, 64):
        fail("defaults differ from client.hpp's ClientOptions")
    options.cache_slots = 1024
    endpoint = Endpoint(b"127.0.0.1", port)
    client = C.c_void_p()
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(options), C.byref(client)), OK, "create", lib)

    listing, count = C.POINTER(MapListing)(), C.c_size_t()
    expect(lib.shadowtile_client_list_maps(client, C.byref(listing), C.byref(count)), OK, "list_maps", lib)
    names = [(listing[i].name.decode(), listing[i].encoding.decode(), listing[i].resolution_log2)
             for i in range(count.value)]
    lib.shadowtile_free_map_listings(listing)
    if names != [("city", "dagmh", 8)]:
        fail("list_maps: %s" % names)

    m = C.c_void_p()
    expect(lib.shadowtile_client_open_map(client, b"city", C.byref(m)), OK, "open_map", lib)
    info = MapInfo()
    expect(lib.shadowtile_map_get_info(m, C.byref(info)), OK, "get_info", lib)
    if (info.name, info.encoding, info.finest_level, info.sun, info.has_deep, info.slices) != \
            (b"city", b"dagmh", 8, 1, 0, 0) or info.tile_count == 0:
        fail("map info: %s" % [(f, getattr(info, f)) for f, _ in MapInfo._fields_])

    side = 1 << info.finest_level
    resident = C.c_int32(0)
    deadline = time.time() + 60
    while not resident.value:
        expect(lib.shadowtile_map_request_region(m, 8, 0, 0, side, side, 1, None), OK, "request_region", lib)
        expect(lib.shadowtile_map_region_resident(m, 8, 0, 0, side, side, C.byref(resident)), OK, "resident", lib)
        if time.time() > deadline:
            fail("the map is not resident after 60 s")
        time.sleep(0.005)

    n = len(points)
    pts = (Point * n)(*[Point(*p) for p in points])
    out = (C.c_float * n)()
    expect(lib.shadowtile_map_visibility(m, pts, n, 0, out), OK, "visibility", lib)
    got = [bits(v) for v in out]
    if got != want or got != got_c:
        diff = [i for i in range(n) if got[i] != want[i]]
        fail("ctypes visibility: %d of %d differ from the pack's (first %s)" % (len(diff), n, diff[:3]))
    # Footprints no wider than a texel take the finest level: the unfiltered answers.
    footprints = (C.c_float * n)(*([0.0] * n))
    filt = (C.c_float * n)()
    expect(lib.shadowtile_map_visibility_filtered(m, pts, footprints, n, 0, filt), OK, "visibility_filtered", lib)
    if [bits(v) for v in filt] != want:
        fail("visibility_filtered with zero footprints differs from visibility")
    # PCF: fractions of a 3x3 kernel, in [0, 1], in ninths.
    pcf = (C.c_float * n)()
    expect(lib.shadowtile_map_visibility(m, pts, n, 1, pcf), OK, "visibility pcf 1", lib)
    if any(not (0 <= v <= 1) or abs(v * 9 - round(v * 9)) > 1e-5 for v in pcf):
        fail("PCF answers outside [0, 1] or not in ninths")
    rgb = (Rgb * n)()
    expect(lib.shadowtile_map_transmittance(m, pts, None, n, rgb), OK, "transmittance", lib)
    if any((t.r, t.g, t.b) != (1.0, 1.0, 1.0) for t in rgb):
        fail("transmittance of a map without a deep part is not 1")

    stats, cstats = MapStats(), ClientStats()
    expect(lib.shadowtile_map_get_stats(m, C.byref(stats)), OK, "map stats", lib)
    expect(lib.shadowtile_client_get_stats(client, C.byref(cstats)), OK, "client stats", lib)
    if stats.tiles_received == 0 or stats.tiles_failed != 0 or stats.slots_resident == 0 or stats.cache_hits == 0:
        fail("map stats: received %d, failed %d, resident %d, hits %d" % (
            stats.tiles_received, stats.tiles_failed, stats.slots_resident, stats.cache_hits))
    if not cstats.connected or cstats.connects < 1 or cstats.bytes_received < stats.bytes_received:
        fail("client stats: connected %d, connects %d" % (cstats.connected, cstats.connects))
    cancelled = C.c_size_t(99)
    expect(lib.shadowtile_map_cancel_outside(m, 8, 0, 0, side, side, C.byref(cancelled)), OK, "cancel", lib)
    if cancelled.value != 0:
        fail("cancel_outside the whole map cancelled %d" % cancelled.value)

    # ---- the error model
    if errors:
        fail("the callback was called without an error: %s" % errors)
    bad = C.c_void_p()
    expect(lib.shadowtile_client_open_map(client, b"no_such_map", C.byref(bad)), NOT_FOUND, "unknown map", lib)
    msg = lib.shadowtile_last_error().decode()
    if bad.value is not None or "unknown_map" not in msg or errors != [(NOT_FOUND, msg)]:
        fail("unknown map: handle %s, message %r, callback %s" % (bad.value, msg, errors))
    expect(lib.shadowtile_client_open_map(client, b"../etc", C.byref(bad)), INVALID_ARGUMENT, "bad name", lib)
    expect(lib.shadowtile_client_open_map(client, None, C.byref(bad)), INVALID_ARGUMENT, "NULL name", lib)
    expect(lib.shadowtile_map_visibility(m, pts, n, 5, out), INVALID_ARGUMENT, "pcf_radius 5", lib)
    expect(lib.shadowtile_map_visibility(None, pts, n, 0, out), INVALID_ARGUMENT, "NULL map", lib)
    expect(lib.shadowtile_map_visibility(m, None, 0, 0, None), OK, "empty batch", lib)
    if "pcf_radius" in lib.shadowtile_last_error().decode() or "map is NULL" not in lib.shadowtile_last_error().decode():
        fail("last_error after an empty batch: %r" % lib.shadowtile_last_error())
    seen = []
    t = threading.Thread(target=lambda: seen.append(lib.shadowtile_last_error()))
    t.start()
    t.join()
    if seen != [b""]:
        fail("last_error is not per thread: a new thread sees %r" % seen)
    zero = ClientOptions()
    lib.shadowtile_client_options_default(C.byref(zero))
    zero.cache_slots = 0
    other = C.c_void_p()
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(zero), C.byref(other)), INVALID_ARGUMENT,
           "cache_slots 0", lib)
    expect(lib.shadowtile_client_create(C.byref(endpoint), 0, None, C.byref(other)), INVALID_ARGUMENT,
           "no endpoint", lib)
    # A key the server does not ask for: the client refuses the server, for good.
    keyed = ClientOptions()
    lib.shadowtile_client_options_default(C.byref(keyed))
    secret = (C.c_uint8 * 16)(*range(16))
    keyed.key, keyed.key_size = C.cast(secret, C.POINTER(C.c_uint8)), 16
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(keyed), C.byref(other)), OK, "create", lib)
    keyed.request_timeout_ms = 30000
    t0 = time.time()
    expect(lib.shadowtile_client_open_map(other, b"city", C.byref(bad)), REFUSED, "unasked key", lib)
    if time.time() - t0 > 15:
        fail("the refusal took %.1f s: it waited for request_timeout instead of failing at once" % (time.time() - t0))
    print("capi: refused in %.2f s" % (time.time() - t0))
    refused = ClientStats()
    expect(lib.shadowtile_client_get_stats(other, C.byref(refused)), OK, "client stats", lib)
    lib.shadowtile_client_destroy(other)
    if not refused.refused:
        fail("client stats after a refusal: refused = 0")
    # Nothing listening (a bound socket that never listens refuses connections): open times out.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        quick = ClientOptions()
        lib.shadowtile_client_options_default(C.byref(quick))
        quick.request_timeout_ms = 300
        dead = Endpoint(b"127.0.0.1", s.getsockname()[1])
        expect(lib.shadowtile_client_create(C.byref(dead), 1, C.byref(quick), C.byref(other)), OK, "create", lib)
        expect(lib.shadowtile_client_open_map(other, b"city", C.byref(bad)), TIMEOUT, "no server", lib)
        lib.shadowtile_client_destroy(other)
    lib.shadowtile_set_error_callback(ErrorCallback(), None)

    # A map outlives its client, answering from its cache.
    lib.shadowtile_client_destroy(client)
    expect(lib.shadowtile_map_visibility(m, pts, n, 0, out), OK, "visibility after destroy", lib)
    if [bits(v) for v in out] != want:
        fail("answers changed after the client was destroyed")
    lib.shadowtile_map_close(m)
    lib.shadowtile_client_destroy(None)
    lib.shadowtile_map_close(None)
    print("capi: %d points (%d lit): the pack, examples/c_client, examples/minimal and ctypes agree bit for bit; "
          "error model checked" % (n, sum(1 for b in want if b == "3f800000")))


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "exports":
        check_exports(sys.argv[2])
    elif len(sys.argv) == 9 and sys.argv[1] == "serve":
        check_serve(*sys.argv[2:])
    else:
        print(__doc__)
        sys.exit(2)
