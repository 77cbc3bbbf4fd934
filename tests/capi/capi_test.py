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
import math
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
                ("tls", C.c_int32), ("tls_ca_file", C.c_char_p), ("tls_server_name", C.c_char_p),
                ("cache_bytes", C.c_uint64)]


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


class ViewOptions(C.Structure):
    _fields_ = [("samples_x", C.c_uint32), ("samples_y", C.c_uint32), ("receiver_height", C.c_double),
                ("max_distance", C.c_double), ("priority", C.c_uint16), ("reserved", C.c_uint16 * 3),
                ("time", C.c_double), ("lookahead", C.c_double)]


class ViewStats(C.Structure):
    _fields_ = [(n, C.c_uint32) for n in ("wanted", "kept", "resident", "queued", "cancelled", "ahead")]


class LightCoord(C.Structure):
    _fields_ = [("u", C.c_double), ("v", C.c_double), ("d", C.c_double)]


class Texel(C.Structure):
    _fields_ = [("x", C.c_uint64), ("y", C.c_uint64)]


class Light(C.Structure):
    _fields_ = [("kind", C.c_uint32), ("orthographic", C.c_int32), ("kind_name", C.c_char_p),
                ("origin", Point), ("axis_u", Point), ("axis_v", Point), ("forward", Point),
                ("extent", C.c_double), ("near_plane", C.c_double), ("far_plane", C.c_double),
                ("volume_lo", Point), ("volume_hi", Point), ("params", C.c_double * 18)]


class SceneExtent(C.Structure):
    _fields_ = [("bounds_lo", Point), ("bounds_hi", Point)] + \
               [(n, C.c_double) for n in ("ground", "top", "x0", "x1", "z0", "z1")] + [("points", C.c_uint64)]


class Budget(C.Structure):
    _fields_ = [("dictionary_bytes", C.c_uint64), ("accounted_bytes", C.c_uint64)] + \
               [(n, C.c_uint32) for n in ("dictionary_slots", "tile_slots", "views", "view_slots")] + \
               [(n, C.c_uint64) for n in ("view_tiles_wanted", "view_tiles_over", "view_overflows", "view_refetches")]


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
        "shadowtile_map_visibility_filtered_normal": (C.c_int, [C.c_void_p, P(Point), P(Point), P(C.c_float),
                                                                C.c_size_t, C.c_uint32, C.c_int, P(C.c_float)]),
        "shadowtile_map_transmittance": (C.c_int, [C.c_void_p, P(Point), P(C.c_float), C.c_size_t, P(Rgb)]),
        "shadowtile_map_request_region": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                    C.c_uint64, C.c_uint16, P(C.c_size_t)]),
        "shadowtile_map_cancel_outside": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                    C.c_uint64, P(C.c_size_t)]),
        "shadowtile_map_region_resident": (C.c_int, [C.c_void_p, C.c_uint32, C.c_uint64, C.c_uint64, C.c_uint64,
                                                     C.c_uint64, P(C.c_int32)]),
        "shadowtile_map_get_stats": (C.c_int, [C.c_void_p, P(MapStats)]),
        "shadowtile_view_options_default": (None, [P(ViewOptions)]),
        "shadowtile_map_request_view": (C.c_int, [C.c_void_p, C.c_uint32, P(C.c_double), C.c_uint32, C.c_uint32,
                                                  P(ViewOptions), P(ViewStats)]),
        "shadowtile_map_remove_view": (C.c_int, [C.c_void_p, C.c_uint32, P(C.c_int32)]),
        "shadowtile_map_view_stats": (C.c_int, [C.c_void_p, C.c_uint32, P(ViewStats)]),
        "shadowtile_map_get_light": (C.c_int, [C.c_void_p, P(Light)]),
        "shadowtile_map_to_light": (C.c_int, [C.c_void_p, P(Point), C.c_size_t, P(LightCoord)]),
        "shadowtile_map_to_world": (C.c_int, [C.c_void_p, P(LightCoord), C.c_size_t, P(Point)]),
        "shadowtile_map_texels": (C.c_int, [C.c_void_p, C.c_uint32, P(Point), C.c_size_t, P(Texel)]),
        "shadowtile_map_texel_size": (C.c_int, [C.c_void_p, C.c_uint32, P(Point), C.c_size_t, P(C.c_double)]),
        "shadowtile_map_get_scene_extent": (C.c_int, [C.c_void_p, P(SceneExtent)]),
        "shadowtile_map_get_budget": (C.c_int, [C.c_void_p, P(Budget)]),
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


def scene_extent(lib, m):
    e = SceneExtent()
    expect(lib.shadowtile_map_get_scene_extent(m, C.byref(e)), OK, "scene extent", lib)
    return e


def top_down_camera(e, x0=None, x1=None):
    """An orthographic camera looking straight down on the scene's footprint (column-major),
    or on the strip x0..x1 of it."""
    x0 = e.x0 if x0 is None else x0
    x1 = e.x1 if x1 is None else x1
    vp = [0.0] * 16
    vp[0], vp[12] = 2 / (x1 - x0), -(x1 + x0) / (x1 - x0)
    vp[9], vp[13] = 2 / (e.z1 - e.z0), -(e.z1 + e.z0) / (e.z1 - e.z0)
    vp[6], vp[14] = -1 / (e.top - e.ground + 2), (e.top + 1) / (e.top - e.ground + 2)
    vp[15] = 1.0
    return vp


def check_lookahead(lib, m, e):
    """View look-ahead through the C API: a camera over a strip of the scene moving along x
    with its frame times holds tiles ahead of its motion; the same moves without times hold none."""
    o = ViewOptions()
    lib.shadowtile_view_options_default(C.byref(o))
    if not math.isnan(o.time) or o.lookahead != 0.25:
        fail("view options default: time %r lookahead %r, expected NaN and 0.25" % (o.time, o.lookahead))
    w = (e.x1 - e.x0) / 8
    held = {}
    for timed in (True, False):
        view = 11 if timed else 12
        o.lookahead = 1.0
        ahead = 0
        for k in range(3):
            vp = (C.c_double * 16)(*top_down_camera(e, e.x0 + k * w / 4, e.x0 + w + k * w / 4))
            o.time = 0.1 * k if timed else float("nan")
            vs = ViewStats()
            expect(lib.shadowtile_map_request_view(m, view, vp, 320, 180, C.byref(o), C.byref(vs)), OK,
                   "request_view (look-ahead)", lib)
            ahead = max(ahead, vs.ahead)
        held[timed] = ahead
        removed = C.c_int32(-1)
        expect(lib.shadowtile_map_remove_view(m, view, C.byref(removed)), OK, "remove_view", lib)
    if not held[True] > 0 or held[False] != 0:
        fail("look-ahead: %d tiles ahead with frame times, %d without" % (held[True], held[False]))
    print("capi: a moving camera held %d tiles ahead of its motion" % held[True])


def check_light_and_views(lib, m, pts, n, info):
    """The light transform, the scene extent, a camera's view and the cache's shares."""
    light = Light()
    expect(lib.shadowtile_map_get_light(m, C.byref(light)), OK, "get_light", lib)
    if (light.kind, light.orthographic, light.kind_name) != (0, 1, b"sun") or not light.extent > 0 or \
            not light.far_plane > light.near_plane:
        fail("light: kind %d ortho %d %r extent %g" % (light.kind, light.orthographic, light.kind_name, light.extent))
    lc = (LightCoord * n)()
    back = (Point * n)()
    tx = (Texel * n)()
    size = (C.c_double * n)()
    L = info.finest_level
    expect(lib.shadowtile_map_to_light(m, pts, n, lc), OK, "to_light", lib)
    expect(lib.shadowtile_map_to_world(m, lc, n, back), OK, "to_world", lib)
    expect(lib.shadowtile_map_texels(m, L, pts, n, tx), OK, "texels", lib)
    expect(lib.shadowtile_map_texel_size(m, L, pts, n, size), OK, "texel_size", lib)
    span = max(light.extent, light.far_plane)
    side = 1 << L
    for i in range(n):
        p, c = pts[i], lc[i]
        if max(abs(back[i].x - p.x), abs(back[i].y - p.y), abs(back[i].z - p.z)) > 1e-9 * span:
            fail("to_world(to_light(p)) != p at %d" % i)
        want_t = [min(max(int(v * side), 0), side - 1) if v >= 0 else 0 for v in (c.u, c.v)]
        if 0 <= c.u < 1 and 0 <= c.v < 1 and [tx[i].x, tx[i].y] != want_t:
            fail("texel %d: %s, (u, v) = (%r, %r) says %s" % (i, (tx[i].x, tx[i].y), c.u, c.v, want_t))
        # A sun's texel is the same size everywhere: the box's side over 2^L.
        if abs(size[i] - light.extent / side) > 1e-12 * light.extent:
            fail("texel_size %r, expected extent / 2^L = %r" % (size[i], light.extent / side))
    e = scene_extent(lib, m)
    if not (e.points >= 4 and e.ground <= e.top and e.x0 < e.x1 and e.z0 < e.z1 and
            e.bounds_lo.y <= e.ground <= e.bounds_hi.y):
        fail("scene extent: points %d ground %g top %g x %g..%g" % (e.points, e.ground, e.top, e.x0, e.x1))

    # A camera: its tiles are queued, held and resident; then removed.
    vp = (C.c_double * 16)(*top_down_camera(e))
    vs = ViewStats()
    deadline = time.time() + 60
    while True:
        expect(lib.shadowtile_map_request_view(m, 7, vp, 320, 180, None, C.byref(vs)), OK, "request_view", lib)
        if vs.wanted == 0 or vs.kept == 0 or vs.kept > vs.wanted:
            fail("request_view: wanted %d kept %d" % (vs.wanted, vs.kept))
        if vs.resident == vs.kept:
            break
        if time.time() > deadline:
            fail("the view is not resident after 60 s: %d of %d" % (vs.resident, vs.kept))
        time.sleep(0.005)
    again = ViewStats()
    expect(lib.shadowtile_map_view_stats(m, 7, C.byref(again)), OK, "view_stats", lib)
    if (again.wanted, again.kept, again.resident) != (vs.wanted, vs.kept, vs.resident):
        fail("view_stats differs from request_view's answer")
    budget = Budget()
    expect(lib.shadowtile_map_get_budget(m, C.byref(budget)), OK, "budget", lib)
    # cache_slots mode: every slot holds tiles, the dictionary lies beside them.
    if (budget.views, budget.tile_slots, budget.dictionary_slots) != (1, 1024, 0) or \
            budget.view_tiles_wanted != vs.wanted or not 0 < budget.view_slots < budget.tile_slots or \
            budget.accounted_bytes < budget.dictionary_bytes + budget.tile_slots * info.tile_bytes:
        fail("budget: %s" % [(f, getattr(budget, f)) for f, _ in Budget._fields_])
    removed = C.c_int32(-1)
    expect(lib.shadowtile_map_remove_view(m, 7, C.byref(removed)), OK, "remove_view", lib)
    if removed.value != 1:
        fail("remove_view of a registered view: %d" % removed.value)
    expect(lib.shadowtile_map_remove_view(m, 7, C.byref(removed)), OK, "remove_view again", lib)
    if removed.value != 0:
        fail("remove_view of a removed view: %d" % removed.value)
    check_lookahead(lib, m, e)
    print("capi: light, scene extent and a camera's %d tiles checked through ctypes" % vs.wanted)


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
    expect(lib.shadowtile_map_visibility(m, pts, n, 1, out), OK, "visibility", lib)
    got = [bits(v) for v in out]
    if got != want or got != got_c:
        diff = [i for i in range(n) if got[i] != want[i]]
        fail("ctypes visibility: %d of %d differ from the pack's (first %s)" % (len(diff), n, diff[:3]))
    # Footprints no wider than a texel take the finest level: the unfiltered answers.
    footprints = (C.c_float * n)(*([0.0] * n))
    filt = (C.c_float * n)()
    expect(lib.shadowtile_map_visibility_filtered(m, pts, footprints, n, 1, filt), OK, "visibility_filtered", lib)
    if [bits(v) for v in filt] != want:
        fail("visibility_filtered with zero footprints differs from visibility")
    # PCF takes the kernel side: fractions of a side x side kernel, in [0, 1], in side^2-ths.
    for side_k in (3, 5, 9):
        pcf = (C.c_float * n)()
        expect(lib.shadowtile_map_visibility(m, pts, n, side_k, pcf), OK, "visibility pcf side %d" % side_k, lib)
        k2 = side_k * side_k
        if any(not (0 <= v <= 1) or abs(v * k2 - round(v * k2)) > 1e-4 for v in pcf):
            fail("PCF side %d: answers outside [0, 1] or not in %d-ths" % (side_k, k2))
    # With normals (receiver plane): PCF fractions in side^2-ths; no normals is refused.
    normals = (Point * n)(*([Point(0.0, 1.0, 0.0)] * n))
    plane = (C.c_float * n)()
    expect(lib.shadowtile_map_visibility_filtered_normal(m, pts, normals, footprints, n, 3, 0, plane), OK,
           "visibility_filtered_normal", lib)
    if any(not (0 <= v <= 1) or abs(v * 9 - round(v * 9)) > 1e-4 for v in plane):
        fail("visibility_filtered_normal: answers outside [0, 1] or not in 9-ths")
    expect(lib.shadowtile_map_visibility_filtered_normal(m, pts, None, footprints, n, 3, 0, plane), INVALID_ARGUMENT,
           "visibility_filtered_normal without normals", lib)
    if len(errors) != 1 or "normals is NULL" not in errors[0][1]:
        fail("visibility_filtered_normal without normals: callback %s" % errors)
    errors.clear()  # the error model's checks below start from no error
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

    check_light_and_views(lib, m, pts, n, info)

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
    expect(lib.shadowtile_map_visibility(m, pts, n, 2, out), INVALID_ARGUMENT, "pcf_side 2", lib)
    expect(lib.shadowtile_map_visibility(None, pts, n, 1, out), INVALID_ARGUMENT, "NULL map", lib)
    expect(lib.shadowtile_map_visibility(m, None, 0, 1, None), OK, "empty batch", lib)
    if "pcf_side" in lib.shadowtile_last_error().decode() or "map is NULL" not in lib.shadowtile_last_error().decode():
        fail("last_error after an empty batch: %r" % lib.shadowtile_last_error())
    seen = []
    t = threading.Thread(target=lambda: seen.append(lib.shadowtile_last_error()))
    t.start()
    t.join()
    if seen != [b""]:
        fail("last_error is not per thread: a new thread sees %r" % seen)
    # PCF sides that are not odd 1..9 are refused, nothing written, the message naming the side.
    for side_k in (0, 2, 4, 8, 10, 11, 0xFFFFFFFF):
        marker = (C.c_float * n)(*([-1.0] * n))
        expect(lib.shadowtile_map_visibility(m, pts, n, side_k, marker), INVALID_ARGUMENT, "pcf side %d" % side_k,
               lib)
        expect(lib.shadowtile_map_visibility_filtered(m, pts, footprints, n, side_k, marker), INVALID_ARGUMENT,
               "filtered pcf side %d" % side_k, lib)
        msg = lib.shadowtile_last_error().decode()
        if "pcf_side %d" % side_k not in msg or "odd, 1..9" not in msg or any(v != -1.0 for v in marker):
            fail("pcf side %d: message %r, or answers written" % (side_k, msg))
    # Views: bad arguments are refused with a status and a message, nothing registered.
    vp = (C.c_double * 16)(*top_down_camera(scene_extent(lib, m)))
    for what, args in (("empty viewport", (vp, 0, 360)), ("NULL matrix", (None, 64, 64))):
        expect(lib.shadowtile_map_request_view(m, 3, args[0], args[1], args[2], None, None), INVALID_ARGUMENT,
               what, lib)
    nan = (C.c_double * 16)(*vp)
    nan[5] = float("nan")
    expect(lib.shadowtile_map_request_view(m, 3, nan, 64, 64, None, None), INVALID_ARGUMENT, "NaN matrix", lib)
    singular = (C.c_double * 16)()
    expect(lib.shadowtile_map_request_view(m, 3, singular, 64, 64, None, None), INVALID_ARGUMENT, "singular", lib)
    many = ViewOptions()
    lib.shadowtile_view_options_default(C.byref(many))
    many.samples_x, many.samples_y = 200, 200
    expect(lib.shadowtile_map_request_view(m, 3, vp, 64, 64, C.byref(many), None), INVALID_ARGUMENT, "samples", lib)
    vs = ViewStats()
    expect(lib.shadowtile_map_view_stats(m, 3, C.byref(vs)), NOT_FOUND, "refused views register nothing", lib)
    expect(lib.shadowtile_map_view_stats(m, 7, C.byref(vs)), NOT_FOUND, "a removed view", lib)
    tx = (Texel * n)()
    expect(lib.shadowtile_map_texels(m, 31, pts, n, tx), INVALID_ARGUMENT, "texel level 31", lib)
    zero = ClientOptions()
    lib.shadowtile_client_options_default(C.byref(zero))
    zero.cache_slots = 0
    other = C.c_void_p()
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(zero), C.byref(other)), INVALID_ARGUMENT,
           "cache_slots 0", lib)
    expect(lib.shadowtile_client_create(C.byref(endpoint), 0, None, C.byref(other)), INVALID_ARGUMENT,
           "no endpoint", lib)
    # A memory budget per map (cache_bytes): one too small is refused at open, naming the
    # least budget; that least opens with SHADOWTILE_MIN_TILE_SLOTS (8) slots within it.
    budgeted = ClientOptions()
    lib.shadowtile_client_options_default(C.byref(budgeted))
    if budgeted.cache_bytes != 0:
        fail("default cache_bytes %d, expected 0 (cache_slots mode)" % budgeted.cache_bytes)
    budgeted.cache_bytes = 4096
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(budgeted), C.byref(other)), OK, "create", lib)
    small = C.c_void_p()
    if lib.shadowtile_client_open_map(other, b"city", C.byref(small)) == OK:
        fail("a 4096-byte budget opened the map")
    why = lib.shadowtile_last_error().decode()
    least = re.search(r"set cache_bytes \(--cache-mb\) to at least ([0-9]+) bytes", why)
    if not least or "\n" in why:
        fail("the too-small budget's error does not name the least budget in one line: %r" % why)
    lib.shadowtile_client_destroy(other)
    budgeted.cache_bytes = int(least.group(1))
    expect(lib.shadowtile_client_create(C.byref(endpoint), 1, C.byref(budgeted), C.byref(other)), OK, "create", lib)
    expect(lib.shadowtile_client_open_map(other, b"city", C.byref(small)), OK, "open at the least budget", lib)
    tight = Budget()
    expect(lib.shadowtile_map_get_budget(small, C.byref(tight)), OK, "budget", lib)
    if tight.tile_slots != 8 or tight.accounted_bytes != budgeted.cache_bytes:
        fail("least budget: %d slots, %d of %d bytes" % (tight.tile_slots, tight.accounted_bytes, budgeted.cache_bytes))
    lib.shadowtile_map_close(small)
    lib.shadowtile_client_destroy(other)
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
    expect(lib.shadowtile_map_visibility(m, pts, n, 1, out), OK, "visibility after destroy", lib)
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
