#!/usr/bin/env python3
"""day_report.py DAY: gathers the demo's day (scripts/demo-day) into DAY/day.json and
DAY/day.txt, from what the commands wrote there and nothing else (standard library only):

  builds.tsv          scene, light, then `stack SECONDS BYTES PATH [AREA]` and one
                      `2d SECONDS BYTES PATH AZIMUTH ELEVATION [AREA]` row per sample (the
                      demo's timings of `shadowtile build`; BYTES checked against the file;
                      AREA the ground area one texel covers), `2d_all SECONDS` the wall time
                      of all 2D builds (two at a time); optionally the same suns at twice
                      the resolution (`2d_fine ...` rows, `2d_fine_all SECONDS`) and each as
                      a one-sample sun-path stack (`stack1 ...` rows, `stack1_all SECONDS`)
  stack_build.txt     the stack build's summary line (slices, tiles)
  load/load.json      `shadowtile load --time-sweep` (frames, frame_ms, stack.crossings)
  render_T.txt        `shadowtile render --time T --diff` per time T (the map's view, its
                      ray-traced twin and the differing receivers)
  gpu/view.json       `shadowtile view --time-sweep` (optional: absent when the GPU view
                      failed or was off); gpu_compare_T.txt its frame at T against render_T.png

Exit 0 written (prints day.txt), 1 bad or missing input (one line naming the file)."""
import json
import os
import re
import sys


class BadInput(Exception):
    pass


def read(path):
    try:
        with open(path) as f:
            return f.read()
    except OSError as e:
        raise BadInput("%s: cannot read (%s)" % (path, e.strerror))


def read_json(path):
    try:
        return json.loads(read(path))
    except ValueError as e:
        raise BadInput("%s: not JSON (%s)" % (path, e))


def match(pattern, text, path, what):
    m = re.search(pattern, text, re.M)
    if not m:
        raise BadInput("%s: no %s" % (path, what))
    return m


def builds(day):
    path = os.path.join(day, "builds.tsv")
    out = {"scene": None, "light": None, "stack": None, "packs_2d": [], "all_2d_s": None, "packs_2d_fine": [],
           "all_2d_fine_s": None, "packs_stack1": [], "all_stack1_s": None}
    for n, line in enumerate(read(path).splitlines(), 1):
        f = line.split("\t")
        try:
            if f[0] in ("scene", "light") and len(f) == 2:
                out[f[0]] = f[1]
                continue
            if f[0] in ("2d_all", "2d_fine_all", "stack1_all") and len(f) == 2:
                out["all_" + f[0][:-4] + "_s"] = float(f[1])
                continue
            row = {"seconds": float(f[1]), "bytes": int(f[2]), "path": f[3]}
            if f[0] == "stack" and len(f) in (4, 5):
                out["stack"] = row
            elif f[0] in ("2d", "2d_fine", "stack1") and len(f) in (6, 7):
                row.update(azimuth=float(f[4]), elevation=float(f[5]))
                out["packs_" + f[0]].append(row)
            else:
                raise ValueError
            if len(f) in (5, 7):
                row["texel_ground_area"] = float(f[-1])
                if not row["texel_ground_area"] > 0:
                    raise ValueError
        except (ValueError, IndexError):
            raise BadInput("%s:%d: unexpected row '%s'" % (path, n, line))
        if os.path.exists(row["path"]) and os.path.getsize(row["path"]) != row["bytes"]:
            raise BadInput("%s:%d: %s holds %d bytes, not %d" % (path, n, row["path"], os.path.getsize(row["path"]),
                                                                  row["bytes"]))
    if not out["stack"] or not out["packs_2d"] or not out["scene"] or out["all_2d_s"] is None:
        raise BadInput("%s: needs scene, light, one stack row, 2d rows and 2d_all" % path)
    for k in ("2d_fine", "stack1"):
        if out["packs_" + k] and (len(out["packs_" + k]) != len(out["packs_2d"]) or out["all_%s_s" % k] is None):
            raise BadInput("%s: %s rows need one per 2d row and %s_all" % (path, k, k))
    return out


def render(day, t):
    path = os.path.join(day, "render_%s.txt" % t)
    text = read(path)
    m = match(r"^differing pixels: (\d+) of (\d+) receivers", text, path, "'differing pixels' line")
    mean = match(r"^mean \|map - traced\| light over the receivers: ([0-9.]+)", text, path, "mean difference line")
    ms = match(r"map shadows ([0-9.]+) ms", text, path, "map shadows time")
    slices = match(r"^stack of (\d+) slices: (.*)$", text, path, "'stack of' line")
    r = {"time": float(t), "differing": int(m.group(1)), "receivers": int(m.group(2)),
         "mean_abs_difference": float(mean.group(1)), "map_ms": float(ms.group(1)), "slices": slices.group(2).strip(),
         "image": "render_%s.png" % t, "traced": "render_%s_traced.png" % t, "diff": "render_%s_diff.png" % t}
    r["differing_pct"] = 100.0 * r["differing"] / r["receivers"] if r["receivers"] else 0.0
    return r


def gpu(day, times):
    path = os.path.join(day, "gpu", "view.json")
    if not os.path.exists(path):
        return None
    j = read_json(path)
    frames = j.get("frames")
    # scripts/demo-day: frame 2k at the k-th render time (k = 1..n), time 0 at frame 0.
    if not isinstance(frames, list) or len(frames) != 2 * len(times) + 1:
        raise BadInput("%s: expected %d frames" % (path, 2 * len(times) + 1))
    rows = []
    for k, t in ((2 * i, t) for i, t in enumerate(times, 1)):
        fr = frames[k]
        if abs(float(fr.get("time", -1)) - float(t)) > 1e-9:
            raise BadInput("%s: frame %d is at time %s, the render at %s" % (path, k, fr.get("time"), t))
        cmp_path = os.path.join(day, "gpu_compare_%s.txt" % t)
        cmp = read(cmp_path).strip() if os.path.exists(cmp_path) else ""
        m = re.search(r"(\d+) of (\d+) pixels differ", cmp)
        rows.append({"time": float(t), "frame": k, "image": "gpu_%s.png" % t, "holes_pct": fr.get("holes_pct"),
                     "gpu_ms": fr.get("gpu_ms"), "compare": cmp,
                     "pixels_differ": int(m.group(1)) if m else None, "pixels": int(m.group(2)) if m else None})
    host = [f.get("host_us") for f in frames if isinstance(f.get("host_us"), (int, float))]
    return {"device": j.get("device"), "width": j.get("width"), "height": j.get("height"), "pcf": j.get("pcf"),
            "frames": rows, "holes_pct": [f.get("holes_pct") for f in frames],
            "host_us_max": max(host) if host else None, "twin": j.get("twin")}


def main():
    if len(sys.argv) != 2:
        print("usage: day_report.py DAY", file=sys.stderr)
        return 2
    day = sys.argv[1]
    try:
        b = builds(day)
        times = sorted({f[len("render_"):-len(".txt")] for f in os.listdir(day)
                        if re.fullmatch(r"render_[0-9.]+\.txt", f)}, key=float)
        if not times:
            raise BadInput("%s: no render_T.txt" % day)
        stack_txt_path = os.path.join(day, "stack_build.txt")
        st = match(r"stack of (\d+) slices of (\d+)\^2.*?(\d+) tiles", read(stack_txt_path), stack_txt_path,
                   "'stack of N slices' line")
        load_path = os.path.join(day, "load", "load.json")
        lj = read_json(load_path)
        try:
            fr, fm, cr = lj["frames"], lj["frame_ms"], lj["stack"]["crossings"]
            load = {"rate_fps": lj["options"]["rate_fps"], "duration_s": lj["options"]["duration_s"],
                    "cameras": lj["options"]["cameras"], "slices": lj["stack"]["slices"],
                    "frames": fr["total"], "late": fr["late"], "max_lag_ms": fr["max_lag_ms"],
                    "with_holes": fr["with_holes"], "frame_ms": fm, "crossings": cr,
                    "errors": lj["errors"]["total"], "tiles_received": lj["tiles"]["received"]}
        except (KeyError, TypeError):
            raise BadInput("%s: not a stack map's --time-sweep run (frames, frame_ms, stack.crossings)" % load_path)
        renders = [render(day, t) for t in times]
        g = gpu(day, times)
    except BadInput as e:
        print("day_report.py: %s" % e, file=sys.stderr)
        return 1
    s2 = sum(p["bytes"] for p in b["packs_2d"])
    t2 = b["all_2d_s"]
    j = {"scene": b["scene"], "light": b["light"], "slices": int(st.group(1)), "resolution": int(st.group(2)),
         "stack": {"bytes": b["stack"]["bytes"], "build_s": b["stack"]["seconds"], "tiles": int(st.group(3)),
                   "texel_ground_area": b["stack"].get("texel_ground_area")},
         "packs_2d": {"count": len(b["packs_2d"]), "bytes": s2, "build_s": t2,
                      "build_s_sum_of_each": sum(p["seconds"] for p in b["packs_2d"]), "each": b["packs_2d"]},
         "stack_over_2d_bytes": b["stack"]["bytes"] / s2 if s2 else None,
         "load": load, "renders": renders, "gpu": g}
    def pack_set(key, packs, all_s):  # one more set of packs beside the stack: its sizes and the bytes ratio
        if packs:
            total = sum(p["bytes"] for p in packs)
            j["packs_" + key] = {"count": len(packs), "bytes": total, "build_s": all_s,
                                 "build_s_sum_of_each": sum(p["seconds"] for p in packs), "each": packs}
            j["stack_over_" + key + "_bytes"] = b["stack"]["bytes"] / total if total else None
    fine, one = b["packs_2d_fine"], b["packs_stack1"]
    pack_set("2d_fine", fine, b["all_2d_fine_s"])
    pack_set("stack1", one, b["all_stack1_s"])
    text = []
    text.append("scene %s, light %s: %d slices of %d^2" % (j["scene"], j["light"], j["slices"], j["resolution"]))
    text.append("bytes: stack pack %d B (built in %.2f s) vs %d separate 2D packs %d B (built in %.2f s, two at a "
                "time): stack / 2D = %.3f" % (j["stack"]["bytes"], j["stack"]["build_s"], len(b["packs_2d"]), s2, t2,
                                                 j["stack_over_2d_bytes"]))
    area = b["stack"].get("texel_ground_area")
    def areas(packs):
        a = [p.get("texel_ground_area") for p in packs]
        return None if None in a else (min(a), max(a))
    a2 = areas(b["packs_2d"])
    if area and a2:
        # Texels per unit of ground: the stack's against each 2D pack's (more is finer).
        text.append("texels on the ground: a stack texel covers %.4g units^2 of ground in every slice; a 2D pack's at "
                    "%d^2 %.4g..%.4g (the stack holds %.2f..%.2fx their texels per unit of ground)" % (
                        area, j["resolution"], a2[0], a2[1], a2[0] / area, a2[1] / area))
    if fine:
        af = areas(fine)
        text.append("the same %d suns at %d^2: %d B (built in %.2f s)%s: stack / 2D at %d^2 = %.3f" % (
                        len(fine), 2 * j["resolution"], j["packs_2d_fine"]["bytes"], j["packs_2d_fine"]["build_s"],
                        (", a texel %.4g..%.4g units^2 of ground (%.2f..%.2fx the stack's%s)" % (
                            af[0], af[1], af[0] / area, af[1] / area,
                            ": every one at least as fine" if af[1] <= area else ""))
                        if af and area else "", 2 * j["resolution"], j["stack_over_2d_fine_bytes"]))
    if one:
        ao = areas(one)
        text.append("each sun alone in the stack's frame, a one-sample sun-path stack (its ground square fitted to that "
                    "sun): %d B (built in %.2f s)%s: stack / those = %.3f" % (
                        j["packs_stack1"]["bytes"], j["packs_stack1"]["build_s"],
                        (", a texel %.4g..%.4g units^2 of ground (%.3f..%.3fx the stack's)" % (
                            ao[0], ao[1], ao[0] / area, ao[1] / area)) if ao and area else "",
                        j["stack_over_stack1_bytes"]))
    fm, cr = load["frame_ms"], load["crossings"]
    text.append("sweep: %d camera at %g FPS, the whole day in %g s: %d frames, %d late (max lag %.1f ms), %d with holes; "
                "frame work ms mean %.3f, p50 %.3f, p99 %.3f, max %.3f" % (
                    load["cameras"], load["rate_fps"], load["duration_s"], load["frames"], load["late"],
                    load["max_lag_ms"], load["with_holes"], fm["mean"], fm["p50"], fm["p99"], fm["max"]))
    text.append("slice crossings: %d frames read a slice their previous frame did not; %d with holes; their work ms "
                "mean %.3f, max %.3f; errors %d" % (cr["frames"], cr["with_holes"], cr["mean_ms"], cr["max_ms"],
                                                   load["errors"]))
    text.append("%-6s %-12s %24s %10s %8s   %s" % ("time", "slices read", "receivers differ from rays", "mean |d|",
                                                   "map ms", "GPU frame vs render"))
    for r in renders:
        gr = next((x for x in (g or {}).get("frames", []) if x["time"] == r["time"]), None)
        w = re.search(r"slices (\d+) and (\d+) blended|slice (\d+)", r["slices"])
        pair = (w.group(1) + "+" + w.group(2) if w.group(1) else w.group(3)) if w else "?"
        text.append("%-6g %-12s %8d of %-7d %6.3f%% %10.4f %8.1f   %s" % (
            r["time"], pair, r["differing"], r["receivers"], r["differing_pct"], r["mean_abs_difference"],
            r["map_ms"], ("frame %d, holes %.2f%%; %s" % (gr["frame"], gr["holes_pct"], gr["compare"] or "no comparison"))
            if gr else "no GPU view"))
    if g:
        tw = g.get("twin") or {}
        text.append("GPU view (%s, %sx%s, PCF %s, %d frames sweeping 0..%s): holes %% per frame %s (tiles arrive "
                    "through the shader's feedback); CPU twin of the last frame: %s of %s lookups differ" % (
                        g["device"], g["width"], g["height"], g["pcf"], len(g["holes_pct"]), times[-1],
                        " ".join("%.2f" % h for h in g["holes_pct"]), tw.get("differ"), tw.get("lookups")))
    text = "\n".join(text) + "\n"
    with open(os.path.join(day, "day.json"), "w") as f:
        json.dump(j, f, indent=2)
    with open(os.path.join(day, "day.txt"), "w") as f:
        f.write(text)
    sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
