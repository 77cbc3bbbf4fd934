"""same_pack.py A B [--ignore-params]: exit 0 when two packs hold the same header fields,
build params (unless --ignore-params), skip grid and every tile's bytes (PACK.md offsets).
Cells land in a build's journal in completion order, so tile offsets may differ between
builds; what must match is what each tile holds."""
import struct
import sys


def load(path, with_params):
    d = open(path, "rb").read()
    grid_off, grid_size, index_off, count = struct.unpack_from("<QQQQ", d, 208)
    tiles = {}
    for i in range(count):
        tid, off, stored, raw, crc, kind = struct.unpack_from("<QQIIIB", d, index_off + 32 * i)
        tiles[tid] = (raw, crc, kind, d[off:off + stored])
    params_size, = struct.unpack_from("<Q", d, 192)
    params = d[256:256 + params_size] if with_params else b""
    return d[:184], params, d[grid_off:grid_off + grid_size], tiles


with_params = "--ignore-params" not in sys.argv[3:]
a, b = load(sys.argv[1], with_params), load(sys.argv[2], with_params)
sys.exit(0 if a == b and a[3] else 1)
