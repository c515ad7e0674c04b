"""``tuav-sitl up --view web`` inside a private network namespace: the banner's URL, the
web viewer served there while the stack flies in real time (and, where Chromium is
installed, its picture), Ctrl-C, then the run folder's recording.rrd read back with
rerun's own reader beside the truth.csv it was made from. Prints one JSON line."""

import io
import json
import signal
import sys
import time
import urllib.request
from collections import Counter
from pathlib import Path

from tests.netns.up_session import processes_mentioning, up, wait_banner

#: The live view's picture shows the scene: its grey levels spread (a blank page's are
#: 0) and this many pixels of the tether's colour (tests/test_view_live.py asserts both).
LIVE_SPREAD_MIN = 10.0
LIVE_TETHER_PIXELS_MIN = 20
#: The least real time flown once the viewer is served [s]: the recording's rates are
#: checked over the flight (the fixes, the filter's ellipsoid), which must not be only its
#: start, however soon the picture is taken.
MIN_FLIGHT_S = 20.0
#: The tether's colour in the view (RGB) and how near a pixel must be to count.
TETHER_RGB = (140, 86, 75)
TETHER_RGB_TOLERANCE = 30


def picture(png: bytes) -> dict:
    """What a screenshot of the live view holds: its grey-level spread and its count of
    tether-coloured pixels."""
    import numpy as np
    from chromium_util import image_spread
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)
    return {"spread": image_spread(png),
            "tether_pixels": int((np.abs(img - np.array(TETHER_RGB)).max(axis=2)
                                  < TETHER_RGB_TOLERANCE).sum())}


def shows_the_scene(shot: dict) -> bool:
    """Whether :func:`picture`'s account of a screenshot shows the scene with its
    tether."""
    return (shot["spread"] > LIVE_SPREAD_MIN
            and shot["tether_pixels"] > LIVE_TETHER_PIXELS_MIN)


def main() -> int:
    logdir = Path(sys.argv[1])
    shot_path = Path(sys.argv[2]) if len(sys.argv) > 2 else None
    p = up(logdir, "--view", "web", "--position", "4", "0", "10", "--goto", "6", "2", "12",
           "--duration", "900")
    banner = wait_banner(p)
    # the line under the banner
    view_line = p.stdout.readline()
    out: dict = {"banner": banner, "view_line": view_line}
    try:
        url = view_line.split("viewer): ", 1)[1].split()[0] if "viewer): " in view_line \
            else None
        out["url"] = url
        status = None
        deadline = time.monotonic() + 180
        while url is not None and time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url, timeout=5) as r:
                    status = r.status
                    break
            except OSError:
                time.sleep(1.0)
        out["http_status"] = status
        shot_from = time.monotonic()
        if shot_path is not None and url is not None:
            sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
            from chromium_util import chromium, screenshot

            if chromium() is not None:
                try:
                    # a live scene never stands still: the picture as soon as it shows
                    # the scene with its tether (what test_view_live asserts), at most
                    # after 120 s of drawing (not the 240 s a still page may take)
                    png = screenshot(url, shot_path, size=(960, 540), settle_s=120.0,
                                     until=lambda png: shows_the_scene(picture(png))
                                     ).read_bytes()
                except (TimeoutError, OSError, RuntimeError) as exc:
                    # a software-rendered live scene can outlast the capture's wait on a
                    # busy machine; the served recording's picture is test_view's
                    out["shot_error"] = repr(exc)
                else:
                    out["shot"] = picture(png)
                    out["shot_after_s"] = time.monotonic() - shot_from
        time.sleep(max(0.0, MIN_FLIGHT_S - (time.monotonic() - shot_from)))
    finally:
        p.send_signal(signal.SIGINT)
        so, se = p.communicate(timeout=120)
    out["rc"], out["stdout"], out["stderr"] = p.returncode, so[-2000:], se[-2000:]
    out["left"] = processes_mentioning(str(logdir))
    run = next(logdir.iterdir())
    out["plant_last"] = (run / "plant.log").read_text().strip().splitlines()[-1]
    out["view_log"] = (run / "view.log").read_text()[-2000:]
    out["truth_rows"] = len((run / "truth.csv").read_text().splitlines()) - 1
    from rerun.chunk import RrdReader

    rows: Counter = Counter()
    static = set()
    for chunk in RrdReader(run / "recording.rrd").stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
        else:
            rows[chunk.entity_path] += chunk.num_rows
    out["rows"], out["static"] = dict(rows), sorted(static)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
