#!/usr/bin/env python3
"""browser_check.py: opens HTML report pages in headless Chromium and checks them through the DOM.

    browser_check.py --shots DIR [!]PAGE.html:SECTION,SECTION,...:MIN_FIGURES ...

A page marked ! is broken on purpose: it must fail a check (so the checks can fail).

One browser process for all pages, driven over the DevTools protocol on a pipe
(--remote-debugging-pipe: NUL-terminated JSON on fds 3 and 4, so only the standard
library is needed). For each page: every listed section id is present, at least
MIN_FIGURES <figure>s, every figure holds a drawn <svg> (non-empty box, paths in it) or
an <img>, every <img> loaded (naturalWidth > 0), nothing fetched but local files, and a full-page screenshot is kept as
DIR/<page name>.png. Exit 0 all good, 1 a check failed (one line per failure), 77 no
Chromium (the ctest reports a skip).
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

SKIP = 77
TIMEOUT_S = 30

CHECK_JS = r"""
(async () => {
  const imgs = [...document.images];
  await Promise.all(imgs.map(i => i.complete ? 0 : new Promise(r => { i.onload = i.onerror = r; })));
  const figs = [...document.querySelectorAll('figure')];
  return JSON.stringify({
    ready: document.readyState,
    sections: [...document.querySelectorAll('section[id]')].map(s => s.id),
    images: imgs.map(i => ({src: i.getAttribute('src'), w: i.naturalWidth, h: i.naturalHeight})),
    figures: figs.map(f => {
      const s = f.querySelector('svg'), im = f.querySelector('img');
      const b = s ? s.getBoundingClientRect() : null;
      return {id: f.id, svg: !!s, img: !!im, w: b ? b.width : 0, h: b ? b.height : 0,
              marks: s ? s.querySelectorAll('path, use, rect, line').length : 0};
    }),
    verdict: (document.querySelector('#verdict h2') || {}).textContent || null,
    fetched: performance.getEntriesByType('resource').map(e => e.name),
  });
})()
"""


class Browser:
    def __init__(self, exe, profile):
        to_child_r, self.to_child_w = os.pipe()
        self.from_child_r, from_child_w = os.pipe()

        def fds():  # the child reads commands on fd 3 and writes answers on fd 4
            a, b = os.dup(to_child_r), os.dup(from_child_w)
            os.dup2(a, 3)
            os.dup2(b, 4)
        self.proc = subprocess.Popen(
            [exe, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
             "--disable-dev-shm-usage", "--hide-scrollbars", "--user-data-dir=" + profile,
             "--remote-debugging-pipe", "--allow-file-access-from-files", "about:blank"],
            preexec_fn=fds, pass_fds=(3, 4, to_child_r, from_child_w), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self.next_id, self.buf, self.events = 0, b"", []

    def send(self, method, params=None, session=None):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self.to_child_w, json.dumps(msg).encode() + b"\0")
        want, deadline = self.next_id, time.time() + TIMEOUT_S
        while time.time() < deadline:
            m = self.read()
            if m.get("id") == want:
                if "error" in m:
                    raise RuntimeError("%s: %s" % (method, m["error"].get("message")))
                return m.get("result", {})
            self.events.append(m)
        raise RuntimeError("%s: no answer in %d s" % (method, TIMEOUT_S))

    def read(self):
        while b"\0" not in self.buf:
            chunk = os.read(self.from_child_r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the pipe (exit %s)" % self.proc.poll())
            self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def close(self):
        try:
            self.send("Browser.close")
        except Exception:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def check_page(br, path, sections, min_figures, shots):
    url = "file://" + os.path.abspath(path)
    target = br.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    s = br.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    br.send("Emulation.setDeviceMetricsOverride", {"width": 1280, "height": 900, "deviceScaleFactor": 1,
                                                   "mobile": False}, s)
    br.send("Page.navigate", {"url": url}, s)
    r, deadline = None, time.time() + TIMEOUT_S
    while time.time() < deadline:
        r = json.loads(br.send("Runtime.evaluate", {"expression": CHECK_JS, "awaitPromise": True,
                                                    "returnByValue": True}, s)["result"]["value"])
        if r["ready"] == "complete" and r["sections"]:
            break
        time.sleep(0.05)
    fails = []
    name = os.path.relpath(path)
    for sec in sections:
        if sec not in r["sections"]:
            fails.append("%s: section #%s missing (have %s)" % (name, sec, ",".join(r["sections"])))
    if len(r["figures"]) < min_figures:
        fails.append("%s: %d figures, expected at least %d" % (name, len(r["figures"]), min_figures))
    for f in r["figures"]:
        if not f["svg"] and not f["img"]:
            fails.append("%s: figure %s holds neither a plot nor an image" % (name, f["id"]))
        if f["svg"] and (f["w"] < 100 or f["h"] < 50 or f["marks"] < 10):
            fails.append("%s: plot %s not drawn (%.0fx%.0f px, %d marks)" % (name, f["id"], f["w"], f["h"],
                                                                             f["marks"]))
    for im in r["images"]:
        if im["w"] <= 0 or im["h"] <= 0:
            fails.append("%s: image %s did not load" % (name, im["src"]))
    for u in r["fetched"]:
        if not u.startswith("file:"):
            fails.append("%s: fetched %s (a page must open with no network)" % (name, u))
    if not r["verdict"]:
        fails.append("%s: no verdict heading" % name)
    metrics = br.send("Page.getLayoutMetrics", {}, s)
    size = metrics.get("cssContentSize") or metrics.get("contentSize")
    shot = br.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True,
                                              "clip": {"x": 0, "y": 0, "width": 1280,
                                                       "height": min(size["height"], 16000), "scale": 1}}, s)
    import base64
    out = os.path.join(shots, os.path.relpath(path).replace("/", "_").replace(".html", ".png"))
    with open(out, "wb") as f:
        f.write(base64.b64decode(shot["data"]))
    br.send("Target.closeTarget", {"targetId": target})
    print("%s %s: %d sections, %d figures, %d images, verdict '%s', screenshot %s" % (
        "ok  " if not fails else "FAIL", name, len(r["sections"]), len(r["figures"]), len(r["images"]),
        (r["verdict"] or "").strip(), out))
    return fails


def main():
    args = sys.argv[1:]
    if len(args) < 3 or args[0] != "--shots":
        print(__doc__)
        return 2
    shots, specs = args[1], args[2:]
    exe = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
    if not exe:
        print("SKIP: no chromium on PATH (scripts/deps installs Debian's chromium)")
        return SKIP
    os.makedirs(shots, exist_ok=True)
    fails = []
    with tempfile.TemporaryDirectory(prefix="st-chromium-") as profile:
        br = Browser(exe, profile)
        try:
            for spec in specs:
                broken = spec.startswith("!")
                path, secs, n = spec.lstrip("!").rsplit(":", 2)
                if not os.path.exists(path):
                    fails.append("%s: page was not written" % path)
                    continue
                f = check_page(br, path, [x for x in secs.split(",") if x], int(n), shots)
                if broken:
                    print("ok   %s: broken on purpose, refused (%d findings)" % (path, len(f)) if f else
                          "FAIL %s: broken on purpose, yet every check passed" % path)
                    for x in f:
                        print("       expected: " + x)
                    f = [] if f else ["%s: the checks did not catch a broken page" % path]
                fails += f
        finally:
            br.close()
    for f in fails:
        print("FAIL " + f)
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
