"""Opens an annotated travmap file in rerun's *web* viewer inside headless Chromium
(software WebGL through SwiftShader), takes a screenshot and checks that the
occupancy grid's colours are on screen.

Usage:
    viewer_screenshot.py RERUN_BINARY ANNOTATED.(rrd|mcap) OUT.png [--chromium PATH]
                         [--all-entities] [--grid-entity /travmap/prediction]
                         [--timeout 120] [--window 1600x900] [--min-pixels 1000]

What it does:
 1. By default keeps only the grid entity (and /tf, /tf_static) of the input, so the
    3D view frames the grid and renders fast on a software rasterizer
    (`rerun mcap convert -y ...` for .mcap, `rerun rrd filter --drop-entity ...` for
    .rrd). --all-entities serves the file as it is (point clouds included; slower).
 2. Starts `rerun --serve-web` on two free ports on 127.0.0.1 (HTTP web viewer + gRPC
    proxy), in its own process group, with a throw-away XDG config/data dir.
 3. Starts headless Chromium (own process group, throw-away profile) with
    `--use-angle=swiftshader --enable-unsafe-swiftshader` and drives it over the
    DevTools protocol on a pipe (`--remote-debugging-pipe`, no extra packages):
    opens `http://127.0.0.1:W/?url=rerun+http://127.0.0.1:G/proxy&renderer=webgl
    &theme=dark`, waits until the wasm app has started and the recording's size
    (`WebHandle.save_recording()`) stops growing, hides the side/time panels
    (`override_panel_state`) so the 3D view fills the page, then screenshots.
 4. Counts the pixels of the three colours of rerun's `RvizMap` colormap, which the
    ROS 2 OccupancyGrid importer gives GridMaps: free (0) = white, occupied (100) =
    black, unknown (-1) = RViz's grey-green #708986. The dark theme's background is
    (13, 13, 13), so all three stand out. ok = at least two of the three colours each
    cover >= --min-pixels pixels. A blank viewer (measured: 1 colour, 0 grid pixels)
    or rerun's error page (measured: < 110 pixels near #708986 from anti-aliased text,
    no pure black) fails. Screenshots are retried until
    the check passes or the time is up.
 5. Prints one JSON line with what it measured and exits 0 iff ok. On failure it
    also prints (to stderr) the server log tail, Chromium's stderr tail, the page's
    console errors and the page's status text.

Only the standard library is needed (Pillow is used when importable, otherwise a
small built-in PNG decoder), plus a Chromium binary.
"""

import argparse
import base64
import json
import os
import queue
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
import zlib

# rerun's RvizMap colormap (colormap 10, which `rerun mcap convert` gives the GridMaps of
# nav_msgs/msg/OccupancyGrid; RViz's "map" scheme), as measured on screen with rerun 0.41:
# 0 -> white, 100 -> black, -1 -> (112, 137, 134) = #708986.
UNKNOWN_RGB = (112, 137, 134)
UNKNOWN_TOL = 8
FREE_MIN = 250  # every channel >= this: free (white)
OCCUPIED_MAX = 3  # every channel <= this: occupied (black); dark background is 13

# what index.html shows when the wasm app fails to load/start or the browser lacks something
PAGE_ERROR = re.compile(r"error occurred|crashed|not supported|unsupported|support", re.I)

NOISY_STDERR = ("dbus", "Fontconfig", "vaapi", "InitializeSandbox", "idle_linux", "GL Driver Message")


class Failure(Exception):
    pass


class Interrupted(Failure):
    pass


def log(msg):
    print(f"[viewer_screenshot] {msg}", file=sys.stderr, flush=True)


def free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tail(path, lines=30, drop=()):
    try:
        with open(path, "r", errors="replace") as f:
            text = [l.rstrip("\n") for l in f if not any(d in l for d in drop)]
    except OSError:
        return "(no log)"
    text = [re.sub(r"\x1b\[[0-9;]*m", "", l) for l in text]
    return "\n".join(text[-lines:]) or "(empty)"


def kill_group(proc, grace=3.0):
    """SIGTERM the process group started by us, then SIGKILL what is left."""
    if proc is None:
        return
    try:
        pgid = os.getpgid(proc.pid)
    except ProcessLookupError:
        pgid = proc.pid
    for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 2.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(wait)
        except subprocess.TimeoutExpired:
            continue
        # the leader is gone; make sure nothing of its group stays
        try:
            os.killpg(pgid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        break
    try:
        proc.wait(1)
    except subprocess.TimeoutExpired:
        pass


def kill_stragglers(marker):
    """Kill processes (ours: their command line holds our unique temp dir) that left
    their process group, e.g. Chromium helpers."""
    me = os.getpid()
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == me:
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if marker.encode() in cmd:
            try:
                os.kill(int(pid), signal.SIGKILL)
            except OSError:
                pass


# --------------------------------------------------------------------------- rerun

def run_rerun(rerun, args, env, deadline, what):
    left = deadline - time.monotonic()
    if left <= 1:
        raise Failure(f"no time left for {what}")
    try:
        p = subprocess.run([rerun, *args], env=env, capture_output=True, text=True,
                           timeout=left, start_new_session=True)
    except subprocess.TimeoutExpired:
        raise Failure(f"{what} timed out")
    if p.returncode != 0:
        raise Failure(f"{what} failed (exit {p.returncode}):\n{p.stderr[-3000:]}")
    return p


def prepare_input(rerun, src, work, env, deadline, grid_entity, all_entities):
    """Returns the path to serve (an .rrd, or the input itself)."""
    if all_entities:
        return src
    keep = {grid_entity, "/tf", "/tf_static"}
    if src.endswith(".mcap"):
        out = os.path.join(work, "grid.rrd")
        args = ["mcap", "convert", src, "-o", out]
        for topic in sorted(keep):
            args += ["-y", "^" + re.escape(topic) + "$"]
        run_rerun(rerun, args, env, deadline, "rerun mcap convert")
        src_rrd = out
        entities = list_entities(rerun, src_rrd, env, deadline)
        if grid_entity not in entities:
            raise Failure(f"{grid_entity} not in {src}: entities {sorted(entities)}")
        return src_rrd
    entities = list_entities(rerun, src, env, deadline)
    if grid_entity not in entities:
        raise Failure(f"{grid_entity} not in {src}: entities {sorted(entities)}")
    drop = sorted(e for e in entities if e not in keep and not e.startswith("/__"))
    if not drop:
        return src
    out = os.path.join(work, "grid.rrd")
    args = ["rrd", "filter", src, "-o", out]
    for e in drop:
        args += ["--drop-entity", e]
    run_rerun(rerun, args, env, deadline, "rerun rrd filter")
    return out


def list_entities(rerun, rrd, env, deadline):
    p = run_rerun(rerun, ["rrd", "print", rrd], env, deadline, "rerun rrd print")
    return set(re.findall(r"\) - (/\S*) - data columns", p.stdout))


def start_server(rerun, path, work, env, deadline):
    grpc_port, web_port = free_port(), free_port()
    while web_port == grpc_port:
        web_port = free_port()
    log_path = os.path.join(work, "server.log")
    logf = open(log_path, "wb")
    proc = subprocess.Popen(
        [rerun, "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
         "--web-viewer-port", str(web_port), "--hide-welcome-screen", path],
        stdin=subprocess.DEVNULL, stdout=logf, stderr=subprocess.STDOUT, env=env,
        start_new_session=True)
    logf.close()
    url = f"http://127.0.0.1:{web_port}/"
    try:
        while True:
            if proc.poll() is not None:
                raise Failure(f"rerun server exited with {proc.returncode}:\n{tail(log_path)}")
            if time.monotonic() > deadline:
                raise Failure(f"rerun server did not come up:\n{tail(log_path)}")
            try:
                with urllib.request.urlopen(url, timeout=2) as r:
                    ok_http = r.status == 200
                with socket.create_connection(("127.0.0.1", grpc_port), timeout=2):
                    pass
                if ok_http:
                    break
            except OSError:
                pass
            time.sleep(0.3)
    except BaseException:
        kill_group(proc)
        raise
    return proc, log_path, web_port, grpc_port


# ------------------------------------------------------------------------ chromium

def find_chromium(given):
    if given:
        path = given if os.sep in given else shutil.which(given)
        if not path or not os.access(path, os.X_OK):
            raise Failure(f"Chromium binary not found or not executable: {given}")
        return path
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable",
                 "chrome", "headless_shell"):
        path = shutil.which(name)
        if path:
            return path
    raise Failure("no Chromium found (apt-get install chromium, or pass --chromium PATH)")


class Browser:
    """Chromium driven over the DevTools protocol on fds 3/4 (--remote-debugging-pipe)."""

    def __init__(self, binary, work, width, height, extra_args, gl_flags):
        self.profile = os.path.join(work, "chromium-profile")
        self.err_path = os.path.join(work, "chromium.stderr")
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()

        def child_fds():
            a, b = os.dup(to_chrome_r), os.dup(from_chrome_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        args = [binary, "--headless=new", "--remote-debugging-pipe",
                f"--user-data-dir={self.profile}", f"--window-size={width},{height}",
                "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--mute-audio", "--disable-dev-shm-usage",
                "--disable-breakpad", "--disable-crash-reporter",
                "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
                "--no-sandbox"]
        if gl_flags:
            args += ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                     "--ignore-gpu-blocklist"]
        args += list(extra_args) + ["about:blank"]
        self.args = args
        errf = open(self.err_path, "wb")
        self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=errf, stderr=errf,
                                     preexec_fn=child_fds, close_fds=False,
                                     start_new_session=True)
        errf.close()
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._q = queue.Queue()
        self._id = 0
        self.console = []  # errors and warnings from the page
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.session = None

    def _read(self):
        buf = b""
        while True:
            try:
                data = os.read(self._r, 1 << 20)
            except OSError:
                data = b""
            if not data:
                self._q.put(None)
                return
            buf += data
            while b"\0" in buf:
                msg, buf = buf.split(b"\0", 1)
                try:
                    self._q.put(json.loads(msg))
                except ValueError:
                    pass

    def _event(self, m):
        method, p = m.get("method"), m.get("params", {})
        text = None
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "warning", "assert"):
            parts = []
            for a in p.get("args", []):
                parts.append(str(a.get("value", a.get("description", ""))))
            text = f"console.{p.get('type')}: " + " ".join(parts)
        elif method == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            text = "exception: " + str(d.get("exception", {}).get("description", d.get("text")))
        elif method == "Log.entryAdded":
            e = p.get("entry", {})
            if e.get("level") in ("error", "warning"):
                text = f"log.{e.get('level')}: {e.get('text')} {e.get('url', '')}"
        if text:
            self.console.append(text.strip().splitlines()[0][:300])  # first line, no stack
            del self.console[:-200]

    def call(self, method, params=None, deadline=None, session=True):
        self._id += 1
        mid = self._id
        msg = {"id": mid, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        try:
            os.write(self._w, json.dumps(msg).encode() + b"\0")
        except OSError as e:
            raise Failure(f"Chromium pipe closed ({e}); stderr:\n{self.stderr_tail()}")
        while True:
            left = (deadline - time.monotonic()) if deadline else 30
            if left <= 0:
                raise Failure(f"timed out waiting for Chromium's answer to {method}")
            try:
                m = self._q.get(timeout=min(left, 5))
            except queue.Empty:
                if self.proc.poll() is not None:
                    raise Failure(f"Chromium exited ({self.proc.returncode}); stderr:\n"
                                  f"{self.stderr_tail()}")
                continue
            if m is None:
                raise Failure(f"Chromium closed the DevTools pipe; stderr:\n{self.stderr_tail()}")
            if m.get("id") == mid:
                if "error" in m:
                    raise Failure(f"{method}: {m['error']}")
                return m.get("result", {})
            self._event(m)

    def open_page(self, url, width, height, deadline):
        tid = self.call("Target.createTarget", {"url": "about:blank"}, deadline, False)["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": tid, "flatten": True},
                                 deadline, False)["sessionId"]
        for m in ("Runtime.enable", "Log.enable", "Page.enable"):
            self.call(m, deadline=deadline)
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
                  deadline)
        self.call("Emulation.setEmulatedMedia",
                  {"features": [{"name": "prefers-color-scheme", "value": "dark"}]}, deadline)
        self.call("Page.navigate", {"url": url}, deadline)

    def evaluate(self, expression, deadline):
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True},
                      deadline)
        if "exceptionDetails" in r:
            return None
        return r.get("result", {}).get("value")

    def screenshot(self, deadline):
        r = self.call("Page.captureScreenshot", {"format": "png"}, deadline)
        return base64.b64decode(r["data"])

    def stderr_tail(self, lines=25):
        return tail(self.err_path, lines, NOISY_STDERR)

    def close(self):
        try:
            if self.proc.poll() is None:
                self.session = None
                self.call("Browser.close", deadline=time.monotonic() + 3, session=False)
        except Exception:
            pass
        try:
            self.proc.wait(3)
        except subprocess.TimeoutExpired:
            pass
        kill_group(self.proc)
        for fd in (self._w, self._r):
            try:
                os.close(fd)
            except OSError:
                pass


STATE_JS = r"""(() => {
  const h = window._handle;
  const s = {started: !!h, panicked: false, bytes: null, text: null, renderer: null};
  const c = document.getElementById('center_text');
  if (c) s.text = c.innerText.trim().slice(0, 600);
  if (!window.__travmap_gl) {
    try {
      const gl = document.createElement('canvas').getContext('webgl2');
      const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
      window.__travmap_gl = gl ? (ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL)
                                      : gl.getParameter(gl.RENDERER)) : 'no webgl2';
    } catch (e) { window.__travmap_gl = 'error: ' + e; }
  }
  s.renderer = window.__travmap_gl;
  if (h) {
    try { s.panicked = h.has_panicked(); if (s.panicked) s.text = h.panic_message(); } catch (e) {}
    try { s.bytes = h.save_recording().length; } catch (e) { s.bytes = null; }
  }
  return JSON.stringify(s);
})()"""

HIDE_PANELS_JS = r"""(() => {
  for (const p of ['top', 'blueprint', 'selection', 'time'])
    window._handle.override_panel_state(p, 'hidden');
  return true;
})()"""


# ------------------------------------------------------------------------- pixels

def decode_png(data):
    """Returns (width, height, list of (r, g, b)) for 8-bit RGB/RGBA PNGs."""
    try:
        from PIL import Image  # noqa: WPS433
        import io
        im = Image.open(io.BytesIO(data)).convert("RGB")
        raw = im.tobytes()
        w, h = im.size
        return w, h, raw
    except ImportError:
        pass
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise Failure("screenshot is not a PNG")
    pos, idat, w = 8, [], None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or ctype not in (2, 6) or interlace:
                raise Failure(f"unsupported PNG (depth {depth}, type {ctype}, interlace {interlace})")
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + n
    raw = zlib.decompress(b"".join(idat))
    stride = w * bpp
    out = bytearray(w * h * 3)
    prev = bytearray(stride)
    o = 0
    for y in range(h):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if f == 1:
            for i in range(bpp, stride):
                line[i] = (line[i] + line[i - bpp]) & 255
        elif f == 2:
            for i in range(stride):
                line[i] = (line[i] + prev[i]) & 255
        elif f == 3:
            for i in range(stride):
                left = line[i - bpp] if i >= bpp else 0
                line[i] = (line[i] + ((left + prev[i]) >> 1)) & 255
        elif f == 4:
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b = prev[i]
                c = prev[i - bpp] if i >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pr = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pr) & 255
        if bpp == 3:
            out[o:o + stride] = line
        else:
            rgb = bytearray(line)
            del rgb[3::4]
            out[o:o + w * 3] = rgb
        o += w * 3
        prev = line
    return w, h, bytes(out)


def measure(png, min_pixels):
    w, h, raw = decode_png(png)
    counts = {}
    for i in range(0, len(raw), 3):
        key = raw[i:i + 3]
        counts[key] = counts.get(key, 0) + 1
    free = unknown = occupied = 0
    ur, ug, ub = UNKNOWN_RGB
    for key, n in counts.items():
        r, g, b = key[0], key[1], key[2]
        if abs(r - ur) <= UNKNOWN_TOL and abs(g - ug) <= UNKNOWN_TOL and abs(b - ub) <= UNKNOWN_TOL:
            unknown += n
        elif r >= FREE_MIN and g >= FREE_MIN and b >= FREE_MIN:
            free += n
        elif r <= OCCUPIED_MAX and g <= OCCUPIED_MAX and b <= OCCUPIED_MAX:
            occupied += n
    present = sum(1 for n in (free, unknown, occupied) if n >= min_pixels)
    return {
        "width": w, "height": h,
        "grid_pixels": free + unknown + occupied,
        "free_pixels": free, "unknown_pixels": unknown, "occupied_pixels": occupied,
        "grid_colours_present": present,
        "distinct_colours": len(counts),
        "ok": present >= 2,
    }


# --------------------------------------------------------------------------- main

def run(opts, work, result):
    t0 = time.monotonic()
    deadline = t0 + opts.timeout
    rerun = opts.rerun if os.sep in opts.rerun else (shutil.which(opts.rerun) or opts.rerun)
    if not os.path.exists(opts.input):
        raise Failure(f"no such file: {opts.input}")
    width, height = (int(v) for v in opts.window.lower().split("x"))
    env = dict(os.environ)
    # a throw-away config/data home: no analytics state or viewer state of the user's
    env["XDG_CONFIG_HOME"] = os.path.join(work, "config")
    env["XDG_DATA_HOME"] = os.path.join(work, "data")
    env["XDG_CACHE_HOME"] = os.path.join(work, "cache")
    env.setdefault("RUST_LOG", "info")

    chromium = find_chromium(opts.chromium)
    result["chromium"] = chromium
    served = prepare_input(rerun, os.path.abspath(opts.input), work, env, deadline,
                           opts.grid_entity, opts.all_entities)
    result["served"] = "as given" if served == os.path.abspath(opts.input) else "grid only"

    server = browser = png = None
    try:
        server, server_log, web_port, grpc_port = start_server(rerun, served, work, env, deadline)
        result["server_up_s"] = round(time.monotonic() - t0, 1)
        source = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
        url = (f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(source, safe='')}"
               f"&renderer={opts.renderer}&theme=dark&persist=0&hide_welcome_screen")
        result["url"] = url
        browser = Browser(chromium, work, width, height, opts.chromium_arg, not opts.no_gl_flags)
        browser.open_page(url, width, height, deadline)

        state, last_bytes, stable, hidden = {}, None, 0, False
        measured = None
        while True:
            if time.monotonic() > deadline - 2:
                raise Failure("timed out: " + describe(state, measured))
            raw_state = browser.evaluate(STATE_JS, deadline)
            state = json.loads(raw_state) if raw_state else {}
            result["webgl_renderer"] = state.get("renderer")
            if state.get("panicked"):
                raise Failure(f"the viewer panicked: {state.get('text')}")
            if not state.get("started") and PAGE_ERROR.search(state.get("text") or ""):
                raise Failure(f"the viewer did not start; the page says: {state.get('text')!r}")
            if server.poll() is not None:
                raise Failure(f"rerun server exited with {server.returncode}")
            nbytes = state.get("bytes")
            if state.get("started") and nbytes:
                stable = stable + 1 if nbytes == last_bytes else 0
                last_bytes = nbytes
                if stable >= 1 and not hidden:
                    browser.evaluate(HIDE_PANELS_JS, deadline)
                    hidden = True
                    result["loaded_s"] = round(time.monotonic() - t0, 1)
                    time.sleep(opts.settle)
                if hidden:
                    png = browser.screenshot(deadline)
                    measured = measure(png, opts.min_pixels)
                    result["screenshots"] = result.get("screenshots", 0) + 1
                    if measured["ok"]:
                        break
            time.sleep(1.0)
        result["recording_bytes"] = last_bytes
        result.update(measured)
    except Failure as e:
        # keep whatever the page shows, for the record
        if not isinstance(e, Interrupted) and browser is not None and browser.proc.poll() is None:
            try:
                png = browser.screenshot(min(deadline + 10, time.monotonic() + 10))
                result.update({k: v for k, v in measure(png, opts.min_pixels).items() if k != "ok"})
            except Exception:
                pass
        raise
    finally:
        if png:
            with open(opts.output, "wb") as f:
                f.write(png)
            result["screenshot"] = os.path.abspath(opts.output)
        if browser is not None:
            result["console_errors"] = len(browser.console)
            result["_console"] = browser.console[-15:]
            result["_chromium_stderr"] = browser.stderr_tail()
            browser.close()
        if server is not None:
            kill_group(server)
            result["_server_log"] = tail(server_log, 20)
        kill_stragglers(work)
        result["seconds"] = round(time.monotonic() - t0, 1)


def describe(state, measured):
    parts = [f"viewer started={state.get('started')}", f"recording bytes={state.get('bytes')}"]
    if state.get("text"):
        parts.append(f"page text={state.get('text')!r}")
    if measured:
        parts.append(f"last check={measured}")
    return ", ".join(parts)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rerun", help="rerun binary (e.g. target/client-venv/bin/rerun)")
    ap.add_argument("input", help="annotated .rrd or .mcap")
    ap.add_argument("output", help="where to write the screenshot (.png)")
    ap.add_argument("--chromium", help="Chromium binary (default: chromium on PATH)")
    ap.add_argument("--timeout", type=float, default=120.0, help="total time bound, seconds")
    ap.add_argument("--window", default="1600x900", help="page size WxH")
    ap.add_argument("--settle", type=float, default=2.0,
                    help="seconds to wait after loading before the first screenshot")
    ap.add_argument("--min-pixels", type=int, default=1000,
                    help="pixels a grid colour must cover to count as on screen")
    ap.add_argument("--grid-entity", default="/travmap/prediction")
    ap.add_argument("--all-entities", action="store_true",
                    help="serve the file as it is (point clouds too; slower)")
    ap.add_argument("--renderer", default="webgl", choices=("webgl", "webgpu"))
    ap.add_argument("--no-gl-flags", action="store_true",
                    help="do not pass the SwiftShader flags to Chromium (for experiments)")
    ap.add_argument("--chromium-arg", action="append", default=[],
                    help="extra Chromium argument (repeatable)")
    opts = ap.parse_args()

    result = {"ok": False}
    work = tempfile.mkdtemp(prefix="travmap-viewer-")

    def on_signal(signum, _frame):
        for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGALRM):
            signal.signal(sig, signal.SIG_IGN)  # let the cleanup run undisturbed
        raise Interrupted(f"interrupted by signal {signum}")

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGALRM, on_signal)
    signal.alarm(int(opts.timeout) + 30)  # hard stop if something blocks outside our deadlines
    code = 1
    try:
        run(opts, work, result)
        code = 0 if result.get("ok") else 1
        if not result.get("ok"):
            result["error"] = "grid colours not on screen"
    except Failure as e:
        result["error"] = str(e).splitlines()[0][:300]
        log(f"FAILED: {e}")
    except Exception as e:  # noqa: BLE001 - report anything as a failure line
        result["error"] = f"{type(e).__name__}: {e}"
        log(f"FAILED: {type(e).__name__}: {e}")
    finally:
        signal.alarm(0)
        diagnostics = {k: result.pop(k) for k in list(result) if k.startswith("_")}
        if code != 0:
            log("server log tail:\n" + diagnostics.get("_server_log", "(none)"))
            log("chromium stderr tail:\n" + diagnostics.get("_chromium_stderr", "(none)"))
            log("page console (last errors/warnings):\n" + "\n".join(diagnostics.get("_console", [])))
        shutil.rmtree(work, ignore_errors=True)
    result["ok"] = bool(result.get("ok")) and code == 0
    print(json.dumps(result, sort_keys=True), flush=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
