"""Screenshots of a web page in headless Chromium (Debian's ``chromium``), driven over the
DevTools protocol with tornado's websocket client: the page is given time to load (the
Rerun web viewer compiles its WebAssembly and draws with WebGL on SwiftShader) and is
captured once it has stopped changing."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

#: The flags of a headless Chromium that talks to nothing but the page it is given.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync",
                  "--enable-unsafe-swiftshader", "--hide-scrollbars")


def chromium() -> str | None:
    """The Chromium executable, if installed."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _cdp_call(ws_url: str, calls: list[tuple[str, dict]], timeout_s: float) -> list[dict]:
    """Send DevTools ``calls`` (method, params) in order on ``ws_url``; their results."""
    from tornado.ioloop import IOLoop
    from tornado.websocket import websocket_connect

    async def run() -> list[dict]:
        conn = await websocket_connect(ws_url, max_message_size=256 * 1024 * 1024)
        out = []
        for i, (method, params) in enumerate(calls, start=1):
            conn.write_message(json.dumps({"id": i, "method": method, "params": params}))
            while True:
                msg = await conn.read_message()
                if msg is None:
                    raise ConnectionError("DevTools closed the connection")
                data = json.loads(msg)
                if data.get("id") == i:
                    out.append(data.get("result", {}))
                    break
        conn.close()
        return out

    return IOLoop.current().run_sync(run, timeout=timeout_s)


def image_spread(png: bytes) -> float:
    """How much a picture holds: the standard deviation of its grey levels (0 for a blank
    page)."""
    img = np.asarray(Image.open(io.BytesIO(png)).convert("L"), dtype=float)
    return float(img.std())


def screenshot(url: str, out: Path, size: tuple[int, int] = (1600, 900),
               settle_s: float = 240.0, still_s: float = 8.0,
               loading_text: str = "Loading",
               until: Callable[[bytes], bool] | None = None) -> Path:
    """Open ``url`` in headless Chromium and write a PNG of it to ``out`` once the page
    no longer shows ``loading_text`` and has then stayed the same for ``still_s`` [s], or
    (a live page, which never stands still) as soon as ``until`` holds for the PNG; at
    most ``settle_s`` [s] of waiting (then the last picture); returns ``out``."""
    exe = chromium()
    if exe is None:
        raise FileNotFoundError("chromium is not installed")
    with tempfile.TemporaryDirectory(prefix="tuav-chromium-",
                                     ignore_cleanup_errors=True) as profile:
        proc = subprocess.Popen([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                 f"--window-size={size[0]},{size[1]}",
                                 "--remote-debugging-port=0", url],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            port_file = Path(profile) / "DevToolsActivePort"
            deadline = time.monotonic() + 60.0
            while not port_file.is_file() or not port_file.read_text().strip():
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise RuntimeError("chromium did not open its DevTools port")
                time.sleep(0.2)
            port = int(port_file.read_text().split()[0])
            pages: list[dict] = []
            while not pages:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list",
                                            timeout=30) as r:
                    pages = [p for p in json.load(r) if p.get("type") == "page"]
                time.sleep(0.2)
            ws = pages[0]["webSocketDebuggerUrl"]
            last, last_change, shot = b"", time.monotonic(), b""
            end = time.monotonic() + settle_s
            while time.monotonic() < end:
                time.sleep(2.0)
                res = _cdp_call(ws, [
                    ("Runtime.evaluate", {"expression": "document.body ? "
                                          "document.body.innerText : ''",
                                          "returnByValue": True}),
                    ("Page.captureScreenshot", {"format": "png",
                                                "optimizeForSpeed": True})], 240.0)
                shot = base64.b64decode(res[1]["data"])
                if loading_text in str(res[0].get("result", {}).get("value", "")):
                    last, last_change = b"", time.monotonic()
                    continue
                if until is not None and until(shot):
                    break
                small = np.asarray(Image.open(io.BytesIO(shot)).convert("L").resize((160, 90)))
                key = small.tobytes()
                if key != last:
                    last, last_change = key, time.monotonic()
                elif time.monotonic() - last_change >= still_s and image_spread(shot) > 5.0:
                    break
            out.write_bytes(shot)
            return out
        finally:
            # chromium and its helper processes, all in its session
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
