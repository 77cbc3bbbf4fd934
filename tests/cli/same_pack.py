"""same_pack.py A B [--ignore-params]: exit 0 when two packs hold the same header fields,
build params (unless --ignore-params), skip grid and every tile's bytes (PACK.md offsets).
Cells land in a build's journal in completion order, so tile offsets may differ between
builds; what must match is what each tile holds."""
import struct
import sys
import zlib


def entries(d, index_off, count):
    """(id, offset, stored, raw, crc, kind) per tile: the plain index, or with feature
    payloads_only (bit 8) the compact one ("STIZ", size, zlib of the columns; offsets
    implied from the journal's start)."""
    if not struct.unpack_from("<I", d, 20)[0] & (1 << 8):
        return [struct.unpack_from("<QQIIIB", d, index_off + 32 * i) for i in range(count)]
    c = zlib.decompress(d[index_off + 8:])
    n, out, tid, off = count, [], 0, struct.unpack_from("<Q", d, 200)[0]
    for i in range(n):
        tid += struct.unpack_from("<Q", c, 8 * i)[0]
        stored, raw, crc = (struct.unpack_from("<I", c, o * n + 4 * i)[0] for o in (8, 12, 16))
        out.append((tid, off, stored, raw, crc, c[20 * n + i]))
        off += stored
    return out


def load(path, with_params):
    d = open(path, "rb").read()
    grid_off, grid_size, index_off, count = struct.unpack_from("<QQQQ", d, 208)
    tiles = {}
    for tid, off, stored, raw, crc, kind in entries(d, index_off, count):
        tiles[tid] = (raw, crc, kind, d[off:off + stored])
    params_size, = struct.unpack_from("<Q", d, 192)
    params = d[256:256 + params_size] if with_params else b""
    return d[:184], params, d[grid_off:grid_off + grid_size], tiles


with_params = "--ignore-params" not in sys.argv[3:]
a, b = load(sys.argv[1], with_params), load(sys.argv[2], with_params)
sys.exit(0 if a == b and a[3] else 1)
