#!/usr/bin/env python3
"""scripts/soak_report.py: figures and verdict of a soak (scripts/soak, loadgen/LOAD.md "Soak").

Reads OUT/soak.jsonl (one `shadowtile stats` sample per line) and OUT/load/load.json (the
load report); writes OUT/soak.json and OUT/soak.txt; prints soak.txt; exits 1 if a check
fails. The rules (also in LOAD.md):
  steady window  from the first sample with every load connection open (t_full) for the
                 load's duration less one interval;
  memory flat    baseline = server RSS at the first sample >= t_full + warm-up; every
                 sample in the last quarter of the window <= baseline + max(10 %, 16 MiB);
  server memory  server VmHWM (peak RSS, whole run) <= --max-rss-mib;
  errors         load errors 0 (CRC, decode, failed, protocol, connect failures), server
                 Error/TileError frames, protocol errors, timeouts and rejected connections 0,
                 every stats sample answered, load exit code 0;
  tiles lost     the load drained (every requested tile received, cancelled or failed) and
                 none failed;
  connections    connections open >= C + 1 (the monitor's own) in every steady sample, and
                 the load's clients never disconnected.
"""
import argparse
import json
import os
import sys

MIB = 1048576.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", required=True)
    ap.add_argument("--seconds", type=float, required=True)
    ap.add_argument("--warmup", type=float, required=True)
    ap.add_argument("--connections", type=int, required=True)
    ap.add_argument("--cameras", type=int, required=True)
    ap.add_argument("--rate", type=float, required=True)
    ap.add_argument("--cache-mb", type=float, required=True)
    ap.add_argument("--max-rss-mib", type=float, required=True)
    ap.add_argument("--load-rc", type=int, required=True)
    ap.add_argument("--stats-rc", type=int, required=True)
    ap.add_argument("--elapsed", type=float, default=0)
    ap.add_argument("--command", default="")
    a = ap.parse_args()

    samples = []
    with open(os.path.join(a.out, "soak.jsonl")) as f:
        for line in f:
            if line.strip():
                samples.append(json.loads(line))
    load_path = os.path.join(a.out, "load", "load.json")
    load = json.load(open(load_path)) if os.path.exists(load_path) else None

    def proc(s, name, key):
        p = s.get("proc", {}).get(name, {})
        return p.get(key, 0) if p.get("alive") else None

    rows = [s for s in samples if "connections_open" in s]
    want_open = a.connections + 1  # the monitor's own connection counts too
    t_full = next((s["t_s"] for s in rows if s["connections_open"] >= want_open), None)
    interval = rows[1]["t_s"] - rows[0]["t_s"] if len(rows) > 1 else 2.0
    checks = {}
    notes = []
    fig = {"command": a.command, "cameras": a.cameras, "connections": a.connections, "rate_fps": a.rate,
           "cache_mb_per_connection": a.cache_mb, "seconds": a.seconds, "warmup_s": a.warmup,
           "elapsed_s": a.elapsed, "samples": len(samples)}

    if t_full is None:
        checks["connections_held"] = False
        notes.append("never saw all %d load connections open" % a.connections)
        steady = []
    else:
        end = t_full + a.seconds - interval
        steady = [s for s in rows if t_full <= s["t_s"] <= end and proc(s, "load", "rss_bytes") is not None]
        fig["t_all_connected_s"] = t_full
        fig["steady_window_s"] = [t_full, end]
    if steady:
        fig["connections_open_min"] = min(s["connections_open"] for s in steady) - 1
        fig["connections_open_max"] = max(s["connections_open"] for s in steady) - 1
        checks["connections_held"] = fig["connections_open_min"] >= a.connections
        for k in ("requests_per_s", "tiles_per_s", "mib_per_s"):
            v = [s[k] for s in steady]
            fig[k] = {"mean": sum(v) / len(v), "min": min(v), "max": max(v)}
        p99 = [s["p99_us"] for s in steady if s.get("latency_count", 0) > 0]
        fig["server_p99_us"] = {"max": max(p99) if p99 else 0,
                                "median": sorted(p99)[len(p99) // 2] if p99 else 0}
        # Memory: baseline after warm-up, the last quarter of the window against it.
        base = next((s for s in steady if s["t_s"] >= t_full + a.warmup), None)
        last_q = [s for s in steady if s["t_s"] >= t_full + 0.75 * a.seconds]
        srv = [(s["t_s"], proc(s, "server", "rss_bytes")) for s in steady if proc(s, "server", "rss_bytes")]
        if base is None or not last_q or proc(base, "server", "rss_bytes") is None:
            checks["memory_flat"] = False
            notes.append("run too short for the memory rule (warm-up %.0f s)" % a.warmup)
        else:
            b = proc(base, "server", "rss_bytes")
            top = max(proc(s, "server", "rss_bytes") or 0 for s in last_q)
            allowed = max(0.10 * b, 16 * MIB)
            checks["memory_flat"] = top <= b + allowed
            after = [(t, r) for t, r in srv if t >= base["t_s"]]
            slope = 0.0
            if len(after) >= 2:
                mt = sum(t for t, _ in after) / len(after)
                mr = sum(r for _, r in after) / len(after)
                den = sum((t - mt) ** 2 for t, _ in after)
                slope = sum((t - mt) * (r - mr) for t, r in after) / den if den else 0.0
            fig["server_rss_mib"] = {"after_warmup": b / MIB, "last_quarter_max": top / MIB,
                                     "allowed_max": (b + allowed) / MIB,
                                     "max": max(r for _, r in srv) / MIB,
                                     "slope_mib_per_min_after_warmup": slope * 60 / MIB}
        ld = [proc(s, "load", "rss_bytes") for s in steady if proc(s, "load", "rss_bytes")]
        if ld:
            fig["load_rss_mib"] = {"max": max(ld) / MIB, "end": ld[-1] / MIB}
        for name in ("server", "load"):
            cpu = [proc(s, name, "cpu_cores") for s in steady if proc(s, name, "cpu_cores") is not None]
            if cpu:
                fig[name + "_cpu_cores_mean"] = sum(cpu) / len(cpu)
        thr = [proc(s, "load", "threads") for s in steady if proc(s, "load", "threads")]
        if thr:
            fig["load_threads_max"] = max(thr)
    else:
        checks.setdefault("memory_flat", False)
        notes.append("no steady samples")

    hwm = [proc(s, "server", "hwm_bytes") for s in samples if proc(s, "server", "hwm_bytes")]
    fig["server_hwm_mib"] = max(hwm) / MIB if hwm else None
    checks["server_rss_under_limit"] = bool(hwm) and max(hwm) / MIB <= a.max_rss_mib
    lhwm = [proc(s, "load", "hwm_bytes") for s in samples if proc(s, "load", "hwm_bytes")]
    fig["load_hwm_mib"] = max(lhwm) / MIB if lhwm else None

    last = rows[-1] if rows else {}
    c = last.get("counters", {})
    server_err = {k: c.get(k, 0) for k in ("errors", "protocol_errors", "timeouts", "connections_rejected")}
    fig["server_errors"] = server_err
    fig["server_totals"] = {k: c.get(k, 0) for k in ("connections_total", "requests", "tiles_sent", "bytes_sent")}
    stats_failures = sum(1 for s in samples if "stats_error" in s)
    fig["stats_failures"] = stats_failures
    load_errors = load["errors"]["total"] if load else None
    checks["no_errors"] = (load is not None and load_errors == 0 and all(v == 0 for v in server_err.values())
                           and stats_failures == 0 and a.load_rc == 0 and a.stats_rc == 0)
    if a.load_rc != 0:
        notes.append("load exit code %d" % a.load_rc)
    if load:
        t = load["tiles"]
        accounted = t["received"] + t["cancelled"] + t["failed"]
        fig["load"] = {"tiles_requested": t["requested"], "tiles_received": t["received"],
                       "tiles_cancelled": t["cancelled"], "tiles_failed": t["failed"],
                       "drained": load["drained"], "errors": load["errors"],
                       "connects": load.get("connections", {}).get("connects"),
                       "disconnects": load.get("connections", {}).get("disconnects"),
                       "frames": load["frames"]["total"], "frames_late": load["frames"]["late"],
                       "hole_fraction": load["frames"]["hole_fraction"],
                       "cell_latency_ms": {k: load["latency_ms"][k] for k in ("p50", "p99", "max")},
                       "workers": load["options"].get("workers"), "io_threads": load["options"].get("io_threads")}
        checks["no_tile_lost"] = load["drained"] and t["requested"] == accounted and t["failed"] == 0
        disc = load.get("connections", {}).get("disconnects", 0)
        if disc:
            checks["connections_held"] = False
            notes.append("the load's clients disconnected %d time(s)" % disc)
    else:
        checks["no_tile_lost"] = False
        notes.append("no load report")

    ok = all(checks.values())
    fig["checks"] = checks
    fig["notes"] = notes
    fig["verdict"] = "PASS" if ok else "FAIL"

    # The table over time, then the figures and the verdict.
    lines = ["soak: %s" % a.command, "",
             "%7s %6s %9s %9s %8s %9s %11s %10s %9s %8s %8s" % (
                 "t_s", "conns", "req/s", "tiles/s", "MiB/s", "p99_us", "server_MiB", "server_cpu", "load_MiB",
                 "load_cpu", "load_thr")]
    for s in rows:
        sr, lr, lt = proc(s, "server", "rss_bytes"), proc(s, "load", "rss_bytes"), proc(s, "load", "threads")
        sc, lc = proc(s, "server", "cpu_cores"), proc(s, "load", "cpu_cores")
        lines.append("%7.1f %6d %9.0f %9.0f %8.2f %9d %11s %10s %9s %8s %8s" % (
            s["t_s"], s["connections_open"] - 1, s["requests_per_s"], s["tiles_per_s"], s["mib_per_s"],
            s["p99_us"], "%.1f" % (sr / MIB) if sr else "-", "%.2f" % sc if sc is not None else "-",
            "%.1f" % (lr / MIB) if lr else "-", "%.2f" % lc if lc is not None else "-", lt if lt else "-"))
    lines.append("(conns: the server's open connections less the monitor's; p99: server latency, GetTiles receipt")
    lines.append(" -> tile written, of that interval, as its log2 bucket's upper bound; cpu: cores busy)")
    lines.append("")
    lines.append(json.dumps({k: v for k, v in fig.items() if k not in ("checks", "notes", "verdict")}, indent=1))
    lines.append("")
    for k, v in checks.items():
        lines.append("  %-24s %s" % (k, "ok" if v else "FAILED"))
    for n in notes:
        lines.append("  note: " + n)
    lines.append("soak verdict: " + fig["verdict"])
    text = "\n".join(lines) + "\n"
    with open(os.path.join(a.out, "soak.txt"), "w") as f:
        f.write(text)
    with open(os.path.join(a.out, "soak.json"), "w") as f:
        json.dump(fig, f, indent=2)
    sys.stdout.write(text)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
