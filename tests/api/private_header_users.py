#!/usr/bin/env python3
"""The client's back door (client/map_access.hpp: the pack header, the skip grid, the map
as an Evaluator) serves the tests alone: the tools a user runs (render, report, stats,
load, ...) use the public API (shadowtile/client.hpp) as a game does.

  private_header_users.py SOURCE_DIR

Fails, naming each file, when a file outside tests/ and the client library's own sources
(client/) includes client/map_access.hpp, other than the files listed in ALLOWED below,
each with the reason it still does. A listed file that no longer includes it is named
(take it off the list), without failing: the list only ever shrinks."""
import os
import re
import sys

HEADER = "client/map_access.hpp"
# Files outside tests/ and client/ allowed to include it, and why.
ALLOWED = {
    # Benchmarks time the cache's internals: a RemoteMap filled without a Client, the
    # Evaluator behind a Map; they print tables for us, they are not tools a user runs.
    "bench/client_lookups.cpp": "benchmark of the cache's own lookups",
    "bench/frame_path.cpp": "benchmark: replays tile arrivals into a cache without a server",
    "bench/gpu.cpp": "benchmark: fills a cache without a server",
    "bench/serve_loopback.cpp": "benchmark: fills a cache without a Client",
}
INCLUDE = re.compile(r'^\s*#\s*include\s*[<"]' + re.escape(HEADER) + r'[>"]', re.M)


def main(root):
    bad, users = [], set()
    for dirpath, dirnames, filenames in os.walk(root):
        rel_dir = os.path.relpath(dirpath, root)
        dirnames[:] = [d for d in dirnames if not d.startswith(".") and not d.startswith("build")]
        for f in filenames:
            if not f.endswith((".cpp", ".hpp", ".h", ".c", ".cc")):
                continue
            rel = os.path.normpath(os.path.join(rel_dir, f))
            with open(os.path.join(dirpath, f), encoding="utf-8", errors="replace") as fh:
                if not INCLUDE.search(fh.read()):
                    continue
            users.add(rel)
            top = rel.split(os.sep)[0]
            if top in ("tests", "client") or rel in ALLOWED:
                continue
            bad.append(rel)
    stale = sorted(f for f in ALLOWED if f not in users)
    for f in sorted(bad):
        print("FAIL %s includes %s: use the public API (shadowtile/client.hpp); the back door serves tests" % (f, HEADER))
    for f in stale:
        print("note: %s no longer includes %s: take it off ALLOWED in %s" % (f, HEADER, os.path.basename(__file__)))
    if bad:
        sys.exit(1)
    print("ok: %d files include %s, all tests or the client's own (allowed elsewhere: %s)" %
          (len(users), HEADER, ", ".join(sorted(ALLOWED))))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print(__doc__)
        sys.exit(2)
    main(sys.argv[1])
