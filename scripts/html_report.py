#!/usr/bin/env python3
"""html_report.py: one self-contained HTML page per run, from the JSON our tools write.

    html_report.py load   DIR/load.json     -o DIR/load.html   [--command CMD]
    html_report.py report DIR/report.json   -o DIR/report.html [--command CMD]
    html_report.py build  FILE.json         -o FILE.html       [--command CMD]
    html_report.py soak   OUT               -o OUT/soak.html   (OUT/soak.json, soak.jsonl, load/load.json)
    html_report.py index  DIR               -o DIR/index.html  (links every page under DIR, shows view*.png)

Plots are drawn by matplotlib (SVG, fonts as paths, embedded inline), so a page opens
with no network; the index page shows the rendered views from files beside it. Every
page puts the answer first (a verdict or the headline figures), then the evidence; each
figure's caption names the JSON fields it draws and the page names the command that made
the run. Rows and series are taken from the JSON generically: a new encoding, lookup or
refinement series shows up without a change here.

Exit codes: 0 written (the page's path is printed), 1 bad input (one line naming it),
3 matplotlib is missing (the callers then skip the HTML and say so).
"""
import argparse
import html
import io
import json
import math
import os
import sys

EXIT_BAD_INPUT, EXIT_NO_MATPLOTLIB = 1, 3


class BadInput(Exception):
    pass


def load_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as e:
        raise BadInput("%s: cannot read (%s)" % (path, e.strerror))
    except json.JSONDecodeError as e:
        raise BadInput("%s: not JSON (line %d: %s)" % (path, e.lineno, e.msg))


def get(d, *keys, default=None):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def esc(x):
    return html.escape(str(x))


def num(v, digits=3):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return esc(v)
    if isinstance(v, int):
        return "{:,}".format(v)
    if v == 0 or math.isnan(v) or math.isinf(v):
        return esc(v)
    a = abs(v)
    if a >= 1e6 or a < 1e-3:
        return "%.*g" % (digits, v)
    return ("%." + str(max(0, digits - 1 - int(math.floor(math.log10(a))))) + "f") % v


def mib(b):
    return "%.2f MiB" % (float(b) / 1048576) if isinstance(b, (int, float)) else "-"


# ---------------------------------------------------------------------------- figures

class Page:
    """Sections of one HTML page; figures are matplotlib SVG strings."""

    def __init__(self, title, command, sources):
        self.title, self.command, self.sources = title, command, sources
        self.parts = []
        self.figures = 0

    def verdict(self, ok, headline, facts):
        cls = "pass" if ok is True else "fail" if ok is False else "info"
        word = {True: "PASS", False: "FAIL", None: ""}[ok]
        rows = "".join("<tr><th>%s</th><td>%s</td></tr>" % (esc(k), v) for k, v in filter(None, facts))
        self.parts.append('<section id="verdict" class="verdict %s"><h2>%s %s</h2><table>%s</table></section>' %
                          (cls, word, esc(headline), rows))

    def section(self, sid, title, body):
        self.parts.append('<section id="%s"><h2>%s</h2>%s</section>' % (esc(sid), esc(title), body))

    def html(self):
        src = ", ".join("<code>%s</code>" % esc(s) for s in self.sources)
        cmd = "<pre>%s</pre>" % esc(self.command) if self.command else "<p>(command not recorded)</p>"
        return PAGE % {"title": esc(self.title), "body": "\n".join(self.parts), "cmd": cmd, "src": src}


PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>%(title)s</title>
<style>
body{font-family:sans-serif;margin:1.5em auto;max-width:1200px;color:#222;padding:0 1em}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em}
.verdict{padding:.5em 1em;border-radius:6px;margin-bottom:1em}
.pass{background:#e3f6e3;border:2px solid #2a8a2a}.fail{background:#fbe3e3;border:2px solid #b22}
.info{background:#eef2f8;border:2px solid #6c8ebf}
table{border-collapse:collapse;font-size:.9em}th,td{padding:.15em .6em;text-align:left;vertical-align:top}
table.data td,table.data th{border-bottom:1px solid #ddd}table.data td{font-variant-numeric:tabular-nums}
figure{margin:1em 0}figcaption{font-size:.85em;color:#555}
figure svg{max-width:100%%;height:auto}
.views{display:flex;gap:1em;flex-wrap:wrap}.views figure{flex:1;min-width:280px}
.views img{width:100%%;border:1px solid #ccc}
pre{background:#f4f4f4;padding:.5em;overflow-x:auto;white-space:pre-wrap}
</style></head><body>
<h1>%(title)s</h1>
%(body)s
<section id="provenance"><h2>How this was made</h2>%(cmd)s<p>Data: %(src)s. Plots: matplotlib, from those
files only.</p></section>
</body></html>
"""


def plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as p
    p.rcParams.update({"svg.fonttype": "path", "svg.hashsalt": "shadowtile", "font.size": 10,
                       "axes.grid": True, "grid.alpha": 0.3, "legend.framealpha": 0.9})
    return p


def plain_log_ticks(fig):
    """Log axes labelled 0.5, 2, 100 rather than 5x10^-1; minor labels only inside two decades."""
    from matplotlib.ticker import FuncFormatter, NullFormatter
    g = FuncFormatter(lambda v, _: "%g" % v)
    for ax in fig.axes:
        for axis, scale, lim in ((ax.xaxis, ax.get_xscale(), ax.get_xlim()), (ax.yaxis, ax.get_yscale(), ax.get_ylim())):
            if scale != "log" or axis.get_major_formatter().__class__.__name__ == "FixedFormatter":
                continue
            axis.set_major_formatter(g)
            lo, hi = sorted(lim)
            if lo > 0 and hi / lo < 10:  # under a decade: label every minor tick
                axis.set_minor_formatter(g)
            elif lo > 0 and hi / lo < 1000:  # label 2 and 5 of each decade too
                axis.set_minor_formatter(FuncFormatter(
                    lambda v, _: "%g" % v if v > 0 and round(v / 10 ** math.floor(math.log10(v)), 6) in (2, 5) else ""))
            else:
                axis.set_minor_formatter(NullFormatter())


def svg_of(fig):
    p = plt()
    plain_log_ticks(fig)
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None})
    p.close(fig)
    s = buf.getvalue()
    return s[s.index("<svg"):]


def figure(page, fig, caption):
    page.figures += 1
    return '<figure id="fig%d">%s<figcaption>Figure %d. %s</figcaption></figure>' % (
        page.figures, svg_of(fig), page.figures, caption)


def outside_legend(ax):
    """A legend beside the axes, never over the data."""
    h, _ = ax.get_legend_handles_labels()
    if h:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)


def span_is_wide(values):
    v = [x for x in values if isinstance(x, (int, float)) and x > 0]
    return len(v) >= 2 and max(v) / min(v) >= 30


def percentile_axes(ax, count):
    """x = -log10(1 - q): p50, p90, p99, p99.9 equally spaced, as latency people read them."""
    ticks = [(0.0, "p0"), (0.5, "p50"), (0.9, "p90"), (0.99, "p99"), (0.999, "p99.9"), (0.9999, "p99.99"),
             (0.99999, "p99.999")]
    top = 1 - 1.0 / max(count, 2)
    ax.set_xticks([-math.log10(1 - q) for q, _ in ticks if q <= top])
    ax.set_xticklabels([n for q, n in ticks if q <= top])
    ax.set_xlabel("percentile (the rightmost point: the maximum)")


def pct_x(q, count):
    return -math.log10(max(1 - q, 1.0 / max(count, 2)))


def table(headers, rows):
    head = "".join("<th>%s</th>" % esc(h) for h in headers)
    body = "".join("<tr>%s</tr>" % "".join("<td>%s</td>" % c for c in r) for r in rows)
    return '<table class="data"><tr>%s</tr>%s</table>' % (head, body)


# ---------------------------------------------------------------------------- load

def load_page(j, src, command):
    p = plt()
    lat = j.get("latency_ms", {})
    errors = get(j, "errors", "total", default=0)
    drained = j.get("drained", False)
    frames = j.get("frames", {})
    cuts = j.get("cut_residency_ms", {})
    ok = errors == 0 and bool(drained)
    opts = j.get("options", {})
    page = Page("shadowtile load: map '%s', %s path, %s cameras" % (opts.get("map", "?"), opts.get("path", "?"),
                                                                 opts.get("cameras", "?")), command, [src])
    page.verdict(ok, "no errors and every requested tile accounted for" if ok else
                 "errors were counted or tiles were still owed at the end", [
                     ("errors (crc/decode/failed/protocol/connect)", "%s (%s/%s/%s/%s/%s)" % (
                         errors, get(j, "errors", "crc"), get(j, "errors", "decode"), get(j, "errors", "failed"),
                         get(j, "errors", "protocol"), get(j, "errors", "connect_failures"))),
                     ("drained at end", "yes" if drained else "no"),
                     ("frames with holes", "%s of %s (%.2f%%)" % (frames.get("with_holes"), frames.get("total"),
                                                                  100 * frames.get("hole_fraction", 0))),
                     ("frame work mean / p99 / max", "%s / %s / %s ms" % (
                         num(get(j, "frame_ms", "mean")), num(get(j, "frame_ms", "p99")), num(get(j, "frame_ms", "max"))))
                     if get(j, "frame_ms") else None,
                     ("slice crossings: frames / with holes / max work", "%s / %s / %s ms" % (
                         get(j, "stack", "crossings", "frames"), get(j, "stack", "crossings", "with_holes"),
                         num(get(j, "stack", "crossings", "max_ms")))) if get(j, "stack", "crossings") else None,
                     ("tile latency p50 / p99 / max", "%s / %s / %s ms" % (num(lat.get("p50")), num(lat.get("p99")),
                                                                         num(lat.get("max")))),
                     ("cut to full residency p50 / p90 / max", "%s / %s / %s ms (%s of %s cuts)" % (
                         num(cuts.get("p50")), num(cuts.get("p90")), num(cuts.get("max")), cuts.get("completed"),
                         cuts.get("cuts"))),
                     ("cache hit rate", "%.2f%%" % (100 * get(j, "cache", "hit_rate", default=0))),
                 ])

    cols = j.get("series_columns", [])
    ser = j.get("series", [])
    body = ""
    if ser and "t_s" in cols:
        c = {n: i for i, n in enumerate(cols)}
        t = [r[c["t_s"]] for r in ser]

        def rate(name, scale=1.0):
            out_t, out_v = [], []
            for a, b in zip(ser, ser[1:]):
                dt = b[c["t_s"]] - a[c["t_s"]]
                if dt > 0:
                    out_t.append(b[c["t_s"]])
                    out_v.append((b[c[name]] - a[c[name]]) / dt * scale)
            return out_t, out_v
        fig, (a1, a2) = p.subplots(2, 1, figsize=(10, 5.5), sharex=True)
        for name, label in (("frames", "frames / s"), ("frames_with_holes", "frames with holes / s")):
            if name in c:
                a1.plot(*rate(name), label=label, drawstyle="steps-pre")
        a1.set_ylabel("frames per second")
        outside_legend(a1)
        if "tiles_received" in c:
            a2.plot(*rate("tiles_received"), label="tiles received / s", color="C2", drawstyle="steps-pre")
        a2.set_ylabel("tiles per second")
        if "bytes" in c:
            ax3 = a2.twinx()
            ax3.plot(*rate("bytes", 1 / 1048576), label="MiB received / s", color="C3", linestyle="--")
            ax3.set_ylabel("MiB per second")
            ax3.grid(False)
            h1, l1 = a2.get_legend_handles_labels()
            h2, l2 = ax3.get_legend_handles_labels()
            a2.legend(h1 + h2, l1 + l2, loc="upper left", bbox_to_anchor=(1.08, 1.0), borderaxespad=0)
        a2.set_xlabel("time since the start of the run (s)")
        a2.set_xlim(0, max(t) if t else 1)
        body = figure(page, fig, "Frames, frames with holes and tiles per second over the run, from the "
                      "cumulative counters in <code>series</code> (sampled by the load tester).")
    page.section("timeline", "Timeline", body or "<p>no time series in the JSON</p>")

    curve = lat.get("percentiles", [])
    cq = sorted(cuts.get("all", []))
    body = ""
    if curve or cq:
        n = lat.get("count", 0)
        fig, ax = p.subplots(figsize=(10, 4.5))
        if curve:
            ax.plot([pct_x(q, n) for q, _ in curve], [max(v, 1e-3) for _, v in curve], marker=".",
                    label="tile latency")
        if cq:  # the i-th of k sorted values is the (i / (k - 1)) quantile; the last one the maximum
            k = len(cq)
            ax.plot([pct_x(i / (k - 1) if k > 1 else 1.0, k) for i in range(k)], [max(v, 1e-3) for v in cq],
                    marker="x", linestyle="--", label="cut to full residency")
        percentile_axes(ax, max(n, len(cq)))
        ax.set_yscale("log")
        ax.set_ylabel("milliseconds (log)")
        outside_legend(ax)
        body = figure(page, fig, "Latency by percentile: a needed cell from the frame that first needed it to its "
                      "tile's arrival (<code>latency_ms.percentiles</code>, %s cells, %s abandoned%s) and a camera "
                      "cut to every needed tile resident (<code>cut_residency_ms.all</code>, %s cuts)." % (
                          n, lat.get("abandoned", 0), "; no cell waited in this run" if not curve else "", len(cq)))
    page.section("latency", "Latency percentiles", body or "<p>no latency percentiles in the JSON</p>")

    allc = cuts.get("all", [])
    body = ""
    if allc:
        fig, ax = p.subplots(figsize=(10, 3.5))
        ax.bar(range(len(allc)), allc, color="C1", label="cut %d..%d" % (0, len(allc) - 1))
        for q, style in (("p50", ":"), ("p90", "--")):
            if isinstance(cuts.get(q), (int, float)):
                ax.axhline(cuts[q], color="k", linestyle=style, linewidth=1, label="%s %.1f ms" % (q, cuts[q]))
        if span_is_wide(allc):
            ax.set_yscale("log")
        from matplotlib.ticker import MaxNLocator
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("camera cut (in order)")
        ax.set_ylabel("ms to full residency")
        outside_legend(ax)
        body = figure(page, fig, "Time from each camera cut until every tile its view needs is resident "
                      "(<code>cut_residency_ms.all</code>; %s cuts were cut again before that)." %
                      cuts.get("incomplete", 0))
    page.section("cuts", "Cut to residency", body or "<p>no completed cuts in this run</p>")

    flat = []
    for k, v in j.items():
        if isinstance(v, dict) and k not in ("options",):
            for k2, v2 in v.items():
                if not isinstance(v2, (list, dict)):
                    flat.append(("%s.%s" % (k, k2), num(v2)))
    page.section("figures", "All figures", table(["field", "value"], flat) +
                 "<p>Options: <code>%s</code></p>" % esc(json.dumps(opts)))
    return page


# ---------------------------------------------------------------------------- report

def pareto(points):
    """Indices of the points no other point beats on both time and error."""
    best, out = float("inf"), []
    for i in sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1])):
        if points[i][1] < best:
            best = points[i][1]
            out.append(i)
    return out


def report_page(j, src, command):
    p = plt()
    rows = j.get("error_vs_time", [])
    lossless = j.get("lossless_disagreements", {})
    differ = {k: v.get("differing", 0) for k, v in lossless.items() if isinstance(v, dict)}
    ok = all(v == 0 for v in differ.values()) if differ else None
    page = Page("shadowtile report: %s, %s, %s^2 (level %s)" % (j.get("scene"), j.get("light"),
                                                               2 ** j.get("level", 0), j.get("level")), command, [src])
    facts = [("lossless check (vsdag: its slab contract): receivers differing from the full float map", ", ".join(
        "%s %s" % (k, v) for k, v in differ.items()) or "not measured")]
    for enc, r in j.get("refinement", {}).items():
        if isinstance(r, dict) and r.get("points"):
            below = r.get("samples_below_same_memory_float")
            facts.append(("refinement %s" % enc, "error %s at the cut%s -> %s after %s ms%s" % (
                num(r["points"][0][1]),
                " (map preview %s KiB)" % num(r["preview_bytes"] / 1024.0) if "preview_bytes" in r else "",
                num(r.get("final_error")), num(r.get("ms_to_full")),
                "; %s of %d samples below the same-memory float map" % (below, len(r["points"]))
                if below is not None else "")))
    single = [r for r in rows if r.get("pcf_radius", 0) == 0]
    if single:
        b = min(single, key=lambda r: (r.get("error", 1), r.get("ms_per_frame", 0)))
        facts.append(("lowest single-tap error", "%s (%s, level %s): %s at %s ms/frame" % (
            b.get("map"), b.get("lookup"), b.get("level"), num(b.get("error")), num(b.get("ms_per_frame")))))
    contract = " (vsdag: within its slab contract)" if any(
        isinstance(v, dict) and "within_slab" in v for v in lossless.values()) else ""
    page.verdict(ok, "compressed maps answer as the uncompressed full map" + contract if ok else
                 "compressed and uncompressed maps disagree" if ok is False else "", facts)

    # Error vs time: one panel per error metric (every numeric row field named error*),
    # split into single tap and PCF (different metrics), one series per map.
    err_keys = sorted({k for r in rows for k, v in r.items() if k.startswith("error") and isinstance(v, (int, float))})
    body = ""
    for ek in err_keys:
        for kind, sel in (("single tap", lambda r: r.get("pcf_radius", 0) == 0),
                          ("PCF", lambda r: r.get("pcf_radius", 0) != 0)):
            rs = [r for r in rows if sel(r) and isinstance(r.get(ek), (int, float)) and
                  isinstance(r.get("ms_per_frame"), (int, float))]
            if not rs:
                continue
            fig, ax = p.subplots(figsize=(10, 5))
            maps = list(dict.fromkeys(r.get("map") for r in rs))
            pts = [(max(r["ms_per_frame"], 1e-3), max(r[ek], 1e-7)) for r in rs]
            for mi, m in enumerate(maps):
                idx = [i for i, r in enumerate(rs) if r.get("map") == m]
                ax.scatter([pts[i][0] for i in idx], [pts[i][1] for i in idx], color="C%d" % (mi % 10),
                           label=str(m), zorder=3)
                for i in idx:
                    lbl = "%s L%s" % (rs[i].get("lookup", ""), rs[i].get("level", ""))
                    ax.annotate(lbl, pts[i], textcoords="offset points", xytext=(4, 4), fontsize=7, color="#444")
            front = pareto(pts)
            ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], color="k", linewidth=1,
                    linestyle="--", label="Pareto front", zorder=2)
            ax.set_xscale("log" if span_is_wide([x for x, _ in pts]) else "linear")
            ax.set_yscale("log")
            ax.set_xlabel("evaluation time per frame (ms, one thread)")
            ax.set_ylabel(("fraction of receivers wrong" if kind == "single tap" else
                           "mean |PCF - supersampled ray-traced visibility|") + " (log)")
            ax.set_title("%s: %s" % (kind, ek))
            outside_legend(ax)
            body += figure(page, fig, "%s lookups: <code>error_vs_time[].%s</code> against "
                           "<code>ms_per_frame</code>, labelled <i>lookup Llevel</i>; the dashed line joins the "
                           "points nothing beats on both. Errors of 0 are drawn at 1e-7." % (kind, ek))
    page.section("pareto", "Error against evaluation time", body or "<p>no rows</p>")

    # Refinement: every series in `refinement` (columns named), the float maps as levels.
    ref = {k: v for k, v in j.get("refinement", {}).items() if isinstance(v, dict) and v.get("points")}
    flats = {k: v for k, v in j.get("uncompressed_frame0_error", {}).items() if isinstance(v, (int, float))}
    body = ""
    if ref:
        fig, (ax, ax2) = p.subplots(2, 1, figsize=(10, 7), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
        t_end = 1.0
        for i, (name, r) in enumerate(ref.items()):
            cols = r.get("columns", ["ms", "error", "resident_cells"])
            c = {n: k for k, n in enumerate(cols)}
            ms = [max(pt[c["ms"]], 0.01) for pt in r["points"]]
            t_end = max(t_end, max(ms))
            if "error" in c:
                ax.plot(ms, [max(pt[c["error"]], 1e-7) for pt in r["points"]], color="C%d" % (i % 10),
                        drawstyle="steps-post", label=name)
            if "resident_cells" in c and r.get("cells"):
                ax2.plot(ms, [100.0 * pt[c["resident_cells"]] / r["cells"] for pt in r["points"]],
                         color="C%d" % (i % 10), drawstyle="steps-post", label=name)
        styles = [":", "--", "-.", (0, (1, 3))]
        for k, (name, v) in enumerate(flats.items()):
            same = "same mem" in name
            ax.axhline(max(v, 1e-7), color="k" if same else "0.5", linewidth=2 if same else 1,
                       linestyle=styles[k % len(styles)], label=name)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(0.01, t_end * 1.5)
        ax.set_ylabel("fraction of receivers wrong (log)")
        outside_legend(ax)
        ax2.set_xscale("log")
        ax2.set_xlim(0.01, t_end * 1.5)
        ax2.set_ylim(0, 105)
        ax2.set_xlabel("ms since the camera cut (log)")
        ax2.set_ylabel("needed cells resident (%)")
        outside_legend(ax2)
        body = figure(page, fig, "Above: error of frame 0 while its tiles stream in after a cut "
                      "(<code>refinement.*.points</code>), with the uncompressed float maps of frame 0 as "
                      "horizontal lines (<code>uncompressed_frame0_error</code>; the thick one has the "
                      "compressed map's memory). Below: the share of needed cells resident.")
    page.section("refinement", "Refinement after a cut", body or "<p>no refinement series</p>")

    keys = list(dict.fromkeys(k for r in rows for k in r))
    page.section("rows", "All measurements", table(keys, [[num(r.get(k, "")) if k != "bytes" else mib(r.get(k))
                                                           for k in keys] for r in rows]) +
                 table(["encoding", "differing", "within interval", "within slab (vsdag)"],
                       [[esc(k), num(v.get("differing")), num(v.get("within_interval")),
                         num(v.get("within_slab", ""))]
                        for k, v in lossless.items() if isinstance(v, dict)]))
    return page


# ---------------------------------------------------------------------------- build

def build_page(j, src, command):
    p = plt()
    cells = j.get("cells", {})
    done = cells.get("built", 0) + cells.get("resumed", 0) + cells.get("outside_region", 0)
    ok = done == cells["total"] if isinstance(cells.get("total"), int) else None
    page = Page("shadowtile build: %s^2 %s" % (j.get("resolution"), j.get("encoding")), command, [src])
    page.verdict(ok, "every cell of the map built" if ok else "cells missing from the pack" if ok is False else
                 "no cell counts in the JSON", [
        ("pack", "%s, %s tiles (%s index tiles)" % (mib(j.get("pack_bytes")), num(j.get("tiles")),
                                                    num(j.get("index_tiles")))),
        ("cells built / resumed / outside region / total", "%s / %s / %s / %s" % (
            cells.get("built"), cells.get("resumed"), cells.get("outside_region"), cells.get("total"))),
        ("wall time", "%s s (%s texels/s)" % (num(j.get("wall_seconds")), num(j.get("texels_per_second")))),
        ("peak RSS", mib(j.get("peak_rss_bytes"))),
        ("constant grid entries", "%.1f%%" % (100 * j.get("constant_entry_fraction", 0))),
    ])
    st = {k: v for k, v in j.get("stage_thread_seconds", {}).items() if isinstance(v, (int, float))}
    body = ""
    if st:
        fig, ax = p.subplots(figsize=(9, 0.45 * len(st) + 1.2))
        order = ["bvh", "trace", "hierarchy", "cut_encode", "compress_write", "finish"]  # pipeline order
        names = [n for n in order if n in st] + sorted(n for n in st if n not in order)
        ax.barh(names, [st[n] for n in names], color="C0")
        for i, n in enumerate(names):
            ax.annotate("%.3g s" % st[n], (st[n], i), textcoords="offset points", xytext=(3, -3), fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel("thread-seconds (summed over worker threads)")
        if span_is_wide(list(st.values())):
            ax.set_xscale("log")
        body = figure(page, fig, "Time per stage (<code>stage_thread_seconds</code>); wall time %s s." %
                      num(j.get("wall_seconds")))
    page.section("stages", "Time per stage", body or "<p>no stage times</p>")
    lv = {int(k): v for k, v in j.get("stored_bytes_per_tile_level", {}).items()}
    body = ""
    if lv:
        fig, ax = p.subplots(figsize=(9, 3.5))
        ks = sorted(lv)
        ax.bar(ks, [lv[k] for k in ks], color="C1")
        ax.set_yscale("log")
        ax.set_xticks(ks)
        ax.set_xlabel("tile level (hierarchy level the tile's root sits at)")
        ax.set_ylabel("stored bytes (log)")
        body = figure(page, fig, "Bytes stored per tile level (<code>stored_bytes_per_tile_level</code>).")
    page.section("levels", "Bytes per level", body or "<p>no per-level sizes</p>")
    hist = j.get("tile_size_histogram", [])
    body = ""
    if hist:
        fig, ax = p.subplots(figsize=(9, 3.5))
        xs = [max(h.get("max_bytes", 1), 1) for h in hist]
        ax.bar(range(len(hist)), [h.get("tiles", 0) for h in hist], color="C2")
        ax.set_xticks(range(len(hist)))
        ax.set_xticklabels(["<=%s" % (("%d KiB" % (x // 1024)) if x >= 1024 else "%d B" % x) for x in xs],
                           rotation=45, ha="right")
        ax.set_xlabel("stored tile size (bucket upper bound)")
        ax.set_ylabel("tiles")
        if span_is_wide([h.get("tiles", 0) for h in hist]):
            ax.set_yscale("log")
            ax.set_ylabel("tiles (log)")
        body = figure(page, fig, "Tile sizes (<code>tile_size_histogram</code>).")
    page.section("tile_sizes", "Tile size histogram", body or "<p>no histogram</p>")
    flat = [(k, num(v)) for k, v in j.items() if not isinstance(v, (list, dict))]
    page.section("figures", "All figures", table(["field", "value"], flat))
    return page


# ---------------------------------------------------------------------------- soak

def soak_page(out, command):
    p = plt()
    sj = os.path.join(out, "soak.json")
    fig_j = load_json(sj)
    samples = []
    jl = os.path.join(out, "soak.jsonl")
    try:
        with open(jl) as f:
            for n, line in enumerate(f, 1):
                if line.strip():
                    try:
                        samples.append(json.loads(line))
                    except json.JSONDecodeError as e:
                        raise BadInput("%s:%d: not JSON (%s)" % (jl, n, e.msg))
    except OSError as e:
        raise BadInput("%s: cannot read (%s)" % (jl, e.strerror))
    rows = [s for s in samples if "connections_open" in s]
    page = Page("shadowtile soak: %s cameras on %s connections, %s s" % (
        fig_j.get("cameras"), fig_j.get("connections"), num(fig_j.get("seconds"))),
        command or fig_j.get("command", ""), [sj, jl])
    checks = fig_j.get("checks", {})
    facts = [(k, "ok" if v else "<b>FAILED</b>") for k, v in checks.items()]
    facts += [("note", esc(n)) for n in fig_j.get("notes", [])]
    rss = fig_j.get("server_rss_mib", {})
    if rss:
        facts.append(("server RSS after warm-up / last quarter max / allowed", "%s / %s / %s MiB" % (
            num(rss.get("after_warmup")), num(rss.get("last_quarter_max")), num(rss.get("allowed_max")))))
    page.verdict(fig_j.get("verdict") == "PASS", "soak verdict", facts)

    def proc(s, name, key):
        q = s.get("proc", {}).get(name, {})
        return q.get(key) if q.get("alive") else None
    win = fig_j.get("steady_window_s")

    def window(ax):
        if win:
            ax.axvspan(win[0], win[1], color="0.9", zorder=0, label="steady window")
    body = ""
    if rows:
        t = [s["t_s"] for s in rows]
        names = list(dict.fromkeys(n for s in rows for n in s.get("proc", {})))
        fig, ax = p.subplots(figsize=(10, 3.8))
        window(ax)
        for i, n in enumerate(names):
            pts = [(s["t_s"], proc(s, n, "rss_bytes") / 1048576) for s in rows if proc(s, n, "rss_bytes")]
            if pts:
                ax.plot([a for a, _ in pts], [b for _, b in pts], color="C%d" % i, label="%s RSS" % n)
        if rss.get("allowed_max"):
            ax.axhline(rss["allowed_max"], color="r", linestyle="--", linewidth=1, label="memory-flat bound")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("resident memory (MiB)")
        ax.set_ylim(bottom=0)
        outside_legend(ax)
        body += figure(page, fig, "Resident memory of each process (<code>proc.*.rss_bytes</code> per sample).")
        fig, ax = p.subplots(figsize=(10, 3.8))
        window(ax)
        for k, label in (("requests_per_s", "requests / s"), ("tiles_per_s", "tiles / s")):
            ax.plot(t, [s.get(k, 0) for s in rows], label=label)
        ax.set_ylabel("per second")
        ax.set_xlabel("time (s)")
        ax2 = ax.twinx()
        ax2.plot(t, [s["connections_open"] - 1 for s in rows], color="C3", linestyle="--", label="connections open")
        ax2.set_ylabel("connections open")
        ax2.grid(False)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, loc="upper left", bbox_to_anchor=(1.1, 1.0), borderaxespad=0)
        body += figure(page, fig, "Server rates and open connections (less the monitor's) per sample "
                       "(<code>requests_per_s</code>, <code>tiles_per_s</code>, <code>connections_open</code>).")
        pts = [(s["t_s"], s["p99_us"] / 1000.0) for s in rows if s.get("latency_count", 0) > 0 and s.get("p99_us")]
        fig, ax = p.subplots(figsize=(10, 3.5))
        window(ax)
        if pts:
            ax.plot([a for a, _ in pts], [b for _, b in pts], marker=".", label="server p99")
            ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("ms (log; log2 bucket bound)")
        outside_legend(ax)
        body += figure(page, fig, "Server latency p99 of each interval, GetTiles receipt to tile written "
                       "(<code>p99_us</code>).")
    page.section("over_time", "Over time", body or "<p>no samples</p>")
    flat = [(k, esc(json.dumps(v)) if isinstance(v, (dict, list)) else num(v)) for k, v in fig_j.items()
            if k not in ("checks", "notes", "verdict")]
    load_html = os.path.join(out, "load", "load.html")
    link = '<p>The load run: <a href="load/load.html">load/load.html</a></p>' if os.path.exists(load_html) else ""
    page.section("figures", "All figures", link + table(["field", "value"], flat))
    return page


# ---------------------------------------------------------------------------- index

def index_page(d, command):
    page = Page("shadowtile report: %s" % os.path.basename(os.path.abspath(d)), command, [d])
    pages = []
    for root, dirs, files in os.walk(d):
        dirs.sort()
        for f in sorted(files):
            if f.endswith(".html") and not (root == d and f == "index.html"):
                pages.append(os.path.relpath(os.path.join(root, f), d))
    # Each page's own verdict (the heading this script wrote at its top), answer first.
    import re
    rows, failed = [], 0
    for rel in pages:
        try:
            with open(os.path.join(d, rel)) as f:
                m = re.search(r'<section id="verdict" class="verdict (\w+)"><h2>(.*?)</h2>', f.read(200000), re.S)
        except OSError:
            m = None
        cls, head = (m.group(1), html.unescape(m.group(2)).strip()) if m else ("info", "(no verdict)")
        failed += cls == "fail"
        rows.append(['<a href="%s">%s</a>' % (esc(rel), esc(rel)), '<span class="%s">%s</span>' % (cls, esc(head))])
    ok = None if not pages else failed == 0
    page.parts.append('<section id="verdict" class="verdict %s"><h2>%s: %d pages, %d failed</h2>%s</section>' % (
        {True: "pass", False: "fail", None: "info"}[ok], {True: "PASS", False: "FAIL", None: "EMPTY"}[ok],
        len(pages), failed, table(["page", "verdict"], rows)))
    views = [("view.png", "from the server's tiles"), ("view_traced.png", "ray-traced (Embree shadow rays; partial occluders by their transmittance)"),
             ("view_diff.png", "difference (red: map shadow where the rays see light)")]
    present = [(f, c) for f, c in views if os.path.exists(os.path.join(d, f))]
    body = '<div class="views">%s</div>' % "".join(
        '<figure><img src="%s" alt="%s"><figcaption>%s: %s</figcaption></figure>' % (esc(f), esc(c), esc(f), esc(c))
        for f, c in present) if present else "<p>no rendered views in this folder</p>"
    page.section("views", "Rendered views", body)
    gpu = gpu_view_section(d)
    if gpu:
        page.section("gpu", "GPU path: shadowtile view (Vulkan rasterizer)", gpu)
    day = day_section(d)
    if day:
        page.section("day", "A day: the sun over a real open mesh (stack pack)", day)
    return page


def day_section(d):
    """The demo's day (scripts/demo-day, day/day.json from scripts/day_report.py): the stack's
    bytes and build time against the same samples as 2D packs, the 60 FPS sweep's frame work
    and slice crossings, and per time of day the map's view, the ray-traced one and the GPU
    frame side by side."""
    path = os.path.join(d, "day", "day.json")
    if not os.path.exists(path):
        return ""
    j = load_json(path)
    st, p2, ld = j["stack"], j["packs_2d"], j["load"]
    fm, cr = ld["frame_ms"], ld["crossings"]
    facts = [
        "Scene %s; light %s: %d slices of %d^2" % (j["scene"], j["light"], j["slices"], j["resolution"]),
        "Stack pack %s B, built in %s s; the same %d samples as separate 2D packs %s B, built in %s s "
        "(two at a time): stack / 2D bytes %s" % (st["bytes"], num(st["build_s"]), p2["count"], p2["bytes"],
                                                   num(p2["build_s"]), num(j["stack_over_2d_bytes"])),
        "Sweep: %s camera at %s FPS over the whole day in %s s: %s frames, %s late (max lag %s ms), %s with holes; "
        "frame work ms mean %s, p99 %s, max %s" % (ld["cameras"], ld["rate_fps"], ld["duration_s"], ld["frames"],
                                                 ld["late"], num(ld["max_lag_ms"]), ld["with_holes"], num(fm["mean"]),
                                                 num(fm["p99"]), num(fm["max"])),
        "Slice crossings (frames reading a slice their previous frame did not): %s, %s with holes, work ms mean %s, "
        "max %s" % (cr["frames"], cr["with_holes"], num(cr["mean_ms"]), num(cr["max_ms"])),
    ]
    if j.get("packs_2d_fine"):  # the same suns at twice the resolution
        pf = j["packs_2d_fine"]
        facts.insert(2, "The same %d suns at %d^2 (day.txt sets each pack's ground area per texel against the "
                        "stack's): %s B: stack / 2D bytes %s" % (pf["count"], 2 * j["resolution"], pf["bytes"],
                                                                num(j["stack_over_2d_fine_bytes"])))
    if j.get("packs_stack1"):  # each sun alone in the stack's frame
        facts.insert(2, "The same %d suns one at a time as one-sample stacks (the same ground frame, fitted to each "
                        "sun): %s B: stack / those bytes %s" % (j["packs_stack1"]["count"], j["packs_stack1"]["bytes"],
                                                                num(j["stack_over_stack1_bytes"])))
    parts = ["<ul>%s</ul>" % "".join("<li>%s</li>" % esc(x) for x in facts)]
    if os.path.exists(os.path.join(d, "day", "load", "load.html")):
        parts.append('<p>The sweep\'s load page: <a href="day/load/load.html">day/load/load.html</a></p>')
    g = j.get("gpu") or {}
    gframes = {f["time"]: f for f in g.get("frames", [])}
    rows, figs = [], []
    for r in j["renders"]:
        gf = gframes.get(r["time"])
        rows.append([num(r["time"]), esc(r["slices"]), "%s of %s (%s%%)" % (r["differing"], r["receivers"],
                                                                          num(r["differing_pct"])),
                     num(r["mean_abs_difference"]), esc(gf["compare"]) if gf else "no GPU view"])
        cells = [("day/" + r["image"], "time %s: map shadows (render --time, PCF 3, filtered)" % num(r["time"])),
                 ("day/" + r["traced"], "time %s: ray-traced (Embree shadow rays, same samples)" % num(r["time"]))]
        if gf:
            cells.append(("day/" + gf["image"], "time %s: GPU view frame %s" % (num(r["time"]), gf["frame"])))
        figs.append('<div class="views">%s</div>' % "".join(
            '<figure><img src="%s" alt="%s"><figcaption>%s</figcaption></figure>' % (esc(f), esc(c), esc(c))
            for f, c in cells if os.path.exists(os.path.join(d, f))))
    parts.append(table(["time", "slices read", "receivers differing from rays", "mean |map - rays|",
                        "GPU frame vs render"], rows))
    parts.extend(figs)
    return "".join(parts)


def gpu_view_section(d):
    """The GPU path's frames (`shadowtile view --out gpu/`, beside index.html), its last frame next
    to `render --filter` from the same camera (view_gpu.png, view_filtered.png), the per-frame
    holes and times, the CPU twin's count and the pixel comparison (gpu/compare.txt)."""
    path = os.path.join(d, "gpu", "view.json")
    if not os.path.exists(path):
        return ""
    j = load_json(path)
    frames = j.get("frames") or []
    figs = [("view_gpu.png", "GPU path, frame %s: the fragment shader's lookups in the GPU tile cache" %
             (frames[-1]["frame"] if frames else "?")),
            ("view_filtered.png", "CPU: render --filter, the client's lookups at each pixel's footprint")]
    parts = ['<p>Device %s, %sx%s, PCF %s, %s frame(s) of one camera; tiles reach the GPU cache only '
             'through the fragment shader\'s feedback (the first frames show holes as coarse shadows).</p>' % (
                 esc(j.get("device", "?")), esc(j.get("width")), esc(j.get("height")), esc(j.get("pcf")), len(frames))]
    present = [(f, c) for f, c in figs if os.path.exists(os.path.join(d, f))]
    parts.append('<div class="views">%s</div>' % "".join(
        '<figure><img src="%s" alt="%s"><figcaption>%s: %s</figcaption></figure>' % (esc(f), esc(c), esc(f), esc(c))
        for f, c in present))
    facts = []
    tw = j.get("twin")
    if isinstance(tw, dict):
        facts.append("CPU twin of the last frame: %s of %s lookups differ (%s%%), max difference %s, holes %s" % (
            tw.get("differ"), tw.get("lookups"), num(tw.get("differ_pct")), num(tw.get("max_difference")),
            tw.get("holes")))
    cmp_path = os.path.join(d, "gpu", "compare.txt")
    if os.path.exists(cmp_path):
        with open(cmp_path) as f:
            facts.append("pixels, view_gpu.png against view_filtered.png: " + f.read().strip())
    if facts:
        parts.append("<ul>%s</ul>" % "".join("<li>%s</li>" % esc(x) for x in facts))
    parts.append(table(["frame", "gpu ms", "shade ms", "requested", "resident", "holes", "holes %"],
                       [[esc(f.get("frame")), num(f.get("gpu_ms")), num(f.get("shade_ms")), esc(f.get("requested")),
                         esc(f.get("resident")), esc(f.get("holes")), num(f.get("holes_pct"))] for f in frames]))
    if os.path.exists(os.path.join(d, "gpu", "contact_sheet.png")):
        parts.append('<figure><img src="gpu/contact_sheet.png" alt="every frame" style="max-width:100%">'
                     '<figcaption>gpu/contact_sheet.png: every frame, first to last</figcaption></figure>')
    return "".join(parts)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("kind", choices=["load", "report", "build", "soak", "index"])
    ap.add_argument("input")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--command", default="")
    a = ap.parse_args()
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        print("html_report.py: matplotlib is not installed (Debian: apt-get install python3-matplotlib)",
              file=sys.stderr)
        return EXIT_NO_MATPLOTLIB
    try:
        if a.kind == "soak":
            page = soak_page(a.input, a.command)
        elif a.kind == "index":
            if not os.path.isdir(a.input):
                raise BadInput("%s: not a folder" % a.input)
            page = index_page(a.input, a.command)
        else:
            j = load_json(a.input)
            if not isinstance(j, dict):
                raise BadInput("%s: expected a JSON object" % a.input)
            page = {"load": load_page, "report": report_page, "build": build_page}[a.kind](j, a.input, a.command)
        text = page.html()
    except BadInput as e:
        print("html_report.py: %s" % e, file=sys.stderr)
        return EXIT_BAD_INPUT
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, ZeroDivisionError) as e:
        print("html_report.py: %s: unexpected content (%s: %s)" % (a.input, type(e).__name__, e), file=sys.stderr)
        return EXIT_BAD_INPUT
    tmp = a.out + ".tmp"
    try:
        with open(tmp, "w") as f:
            f.write(text)
        os.replace(tmp, a.out)
    except OSError as e:
        print("html_report.py: %s: cannot write (%s)" % (a.out, e.strerror), file=sys.stderr)
        return EXIT_BAD_INPUT
    print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
