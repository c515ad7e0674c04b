"""Animation of an offline run: the quadrotor, its tether, the goals and the trail.

:func:`make_animation` reads a run folder written by :mod:`tuav_sitl.offline` and writes
``animation.gif`` (with Pillow, always) and ``animation.mp4`` (when an ``ffmpeg`` executable
is on the PATH) into it. Each frame is drawn once with Agg and fed to both files; the
tether is the lumped tether's nodes the run recorded (the truth, when it was the plant's
model), else recomputed per frame from the UAV's position and the paid-out length with the
plant's catenary (:class:`sitl.tether.Tether`).
"""

from __future__ import annotations

import math
import shutil
import subprocess
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties, findfont
from matplotlib.ticker import MaxNLocator
from PIL import Image, ImageDraw, ImageFont

from tuav_sitl.figure_scene import (
    TetherDrawer,
    draw_goals,
    draw_ground,
    drawn_arm_m,
    quad_outline,
    reached_indices,
    reference_geometry,
    scene_bounds,
    set_scene,
)
from tuav_sitl.run_data import RunData, has_data, load_run

__all__ = ["ANIMATION_SIZE_PX", "FPS", "MAX_FRAMES", "frame_plan", "make_animation"]

#: Width and height of the animation [pixels] (even, as H.264 wants).
ANIMATION_SIZE_PX = (760, 600)
_DPI = 100
#: Playback frame rate [frames per second] and the most frames an animation has: a run up
#: to 10 s plays in real time, a longer one faster (the 75 s circle at 7.5x).
FPS = 15
MAX_FRAMES = 150
#: How long the last frame stays on screen in the GIF [s].
_END_HOLD_S = 1.5
#: At most this many points of the trail are drawn (the path is thinned to it).
_TRAIL_POINTS = 1500
#: Colours the GIF palette must hold exactly: UAV red, trail blue, tether brown, goal
#: purple, black.
_KEY_COLOURS = ("#d62728", "#1f77b4", "#8c564b", "#9467bd", "#000000")
#: The title's size [pt] and its top edge [fraction of the height from the top].
_TITLE_PT = 11.0
_TITLE_TOP = 0.02


def frame_plan(t: np.ndarray, fps: int, max_frames: int,
               speed: float | None) -> tuple[np.ndarray, float]:
    """Sample indices of the frames and the playback speed (simulated seconds per second).

    ``speed`` None: real time if the whole run fits in ``max_frames`` frames at ``fps``,
    else as fast as needed to fit. A given ``speed`` is kept unless it would need more than
    ``max_frames`` frames, in which case the run is sped up to fit. Frames are evenly spread
    in time from the first sample to the last.
    """
    if fps < 1:
        raise ValueError(f"fps: must be >= 1, got {fps!r}")
    if max_frames < 2:
        raise ValueError(f"max_frames: must be >= 2, got {max_frames!r}")
    if speed is not None and not (speed > 0 and math.isfinite(speed)):
        raise ValueError(f"speed: must be finite and > 0, got {speed!r}")
    if len(t) < 2:
        raise ValueError("the time series needs at least two samples")
    duration = float(t[-1] - t[0])
    wanted = duration * fps / (speed if speed is not None else 1.0)
    n = int(min(max_frames, max(2, math.floor(wanted) + 1)))
    times = np.linspace(t[0], t[-1], n)
    idx = np.clip(np.searchsorted(t, times - 1e-9), 0, len(t) - 1)
    real_speed = duration * fps / (n - 1) if duration > 0 else 1.0
    return idx, real_speed


def _ffmpeg_command(ffmpeg: str, size: tuple[int, int], fps: int, out: Path) -> list[str]:
    """The ffmpeg command reading raw RGB frames on stdin: H.264 if the build has it, else
    MPEG-4 part 2."""
    try:
        encoders = subprocess.run([ffmpeg, "-hide_banner", "-encoders"], capture_output=True,
                                  text=True, timeout=20).stdout
    except (OSError, subprocess.SubprocessError):
        encoders = ""
    codec = (["-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "23"]
             if "libx264" in encoders else ["-c:v", "mpeg4", "-q:v", "4", "-pix_fmt", "yuv420p"])
    return [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
            "-s", f"{size[0]}x{size[1]}", "-r", str(fps), "-i", "-", "-an", *codec,
            "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", str(out)]


class _Scene:
    """The figure, its fixed parts, and the artists each frame moves."""

    def __init__(self, run: Any) -> None:
        s, sc = run.series, run.scenario
        self.s, self.sc = s, sc
        self.geo = reference_geometry(sc)
        lo, hi = scene_bounds(s, self.geo)
        self.arm = drawn_arm_m(sc, lo, hi)
        self.tether = TetherDrawer(sc, n_points=50, series=s)
        w, h = ANIMATION_SIZE_PX
        self.fig = Figure(figsize=(w / _DPI, h / _DPI), dpi=_DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        self.fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.93)
        ax = self.ax = self.fig.add_subplot(projection="3d")
        draw_ground(ax, lo, hi)
        ref = s["ref_pos"]
        if has_data(s, "ref_pos"):   # an imported up run has none
            ax.plot(ref[:, 0], ref[:, 1], ref[:, 2], "--", color="0.5", lw=0.8,
                    label="reference path")
        waypoints = sc.trajectory.kind == "waypoints"
        draw_goals(ax, self.geo, reached=0 if waypoints else None)
        # waypoints reached so far: filled stars drawn over the hollow ones
        self.reached = reached_indices(s, self.geo, run.metrics) if waypoints else []
        (self.reached_art,) = ax.plot([], [], [], ls="none", marker="*", markersize=11,
                                      color="#9467bd")
        step = max(1, len(s["t"]) // _TRAIL_POINTS)
        self.trail_idx = np.arange(0, len(s["t"]), step)
        (self.trail,) = ax.plot([], [], [], color="C0", lw=1.6, label="trail")
        (self.cable,) = ax.plot([], [], [], color="#8c564b", lw=1.8,
                                marker="o" if self.tether.lumped else None, markersize=2.5,
                                label="tether (lumped nodes)" if self.tether.lumped
                                else "tether")
        (self.rest,) = ax.plot([], [], [], color="k", lw=1.2)
        (self.front,) = ax.plot([], [], [], color="#d62728", lw=2.2, label="UAV (front red)")
        set_scene(ax, lo, hi, zoom=0.92)
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.yaxis.set_major_locator(MaxNLocator(5))
        ax.view_init(elev=22, azim=-60)
        ax.legend(loc="upper left", fontsize=7, framealpha=0.8)
        # The title changes every frame: Pillow writes it on the finished frame, in
        # matplotlib's bold font (matplotlib's text layout would cost more than the rest of
        # the frame).
        self.font = ImageFont.truetype(findfont(FontProperties(weight="bold")),
                                       round(_TITLE_PT * _DPI / 72.0))
        # Everything else is fixed: draw it once, then per frame restore it and draw only
        # the moving artists over it (a full 3-D redraw costs ~10x more, mostly text).
        self.moving = (self.trail, self.cable, self.rest, self.front, self.reached_art)
        for a in self.moving:
            a.set_animated(True)
        self.canvas.draw()
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)
        self.palette: Image.Image | None = None

    def draw(self, k: int, speed: float) -> Image.Image:
        """Frame of sample ``k`` as an RGB image."""
        s = self.s
        pos = s["pos"]
        tr = self.trail_idx[self.trail_idx < k]
        path = np.vstack((pos[tr], pos[k : k + 1]))
        self.trail.set_data_3d(path[:, 0], path[:, 1], path[:, 2])
        pts = self.tether.points(pos[k], float(s["length"][k]), float(s["t"][k]))
        self.cable.set_data_3d(pts[:, 0], pts[:, 1], pts[:, 2])
        front, rest = quad_outline(pos[k], s["euler"][k], self.arm)
        self.front.set_data_3d(front[:, 0], front[:, 1], front[:, 2])
        self.rest.set_data_3d(rest[:, 0], rest[:, 1], rest[:, 2])
        done = sum(1 for r in self.reached if r <= k)
        p = self.geo.points[:done]
        self.reached_art.set_data_3d(p[:, 0], p[:, 1], p[:, 2])
        title = (f"{self.sc.name}:  t = {s['t'][k]:5.1f} s   L = {s['length'][k]:5.2f} m   "
                 f"(L-bar {s['lbar'][k]:5.2f} m)   {speed:.1f}x speed")
        self.canvas.restore_region(self.background)
        for a in self.moving:
            self.ax.draw_artist(a)
        w, h = self.canvas.get_width_height()
        rgba = Image.frombuffer("RGBA", (w, h), self.canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
        img = rgba.convert("RGB")
        ImageDraw.Draw(img).text((w / 2, _TITLE_TOP * h), title, fill="black",
                                 font=self.font, anchor="ma")
        return img

    def set_palette(self, *frames: Image.Image) -> None:
        """One 256-colour palette for the whole GIF, from sample frames: quantising each
        frame to it is fast, and unchanged pixels keep their index from frame to frame."""
        w, h = frames[0].size
        # swatches of the drawing colours, so that thin lines keep their exact colour
        swatch = 40
        sheet = Image.new("RGB", (w, h * len(frames) + swatch), "white")
        for i, f in enumerate(frames):
            sheet.paste(f, (0, i * h))
        for i, colour in enumerate(_KEY_COLOURS):
            sheet.paste(colour, (i * swatch, h * len(frames), (i + 1) * swatch,
                                 h * len(frames) + swatch))
        self.palette = sheet.quantize(256, method=Image.Quantize.MEDIANCUT)

    def indexed(self, img: Image.Image) -> Image.Image:
        """``img`` in the GIF's palette (no dithering: flat colours stay flat)."""
        assert self.palette is not None
        return img.quantize(palette=self.palette, dither=Image.Dither.NONE)


def make_animation(run_dir: Path, fps: int = FPS, max_frames: int = MAX_FRAMES,
                   speed: float | None = None,
                   on_frame: Callable[[int, int], None] | None = None,
                   run: RunData | None = None) -> list[Path]:
    """Animate the run in ``run_dir``: write ``animation.gif`` there, and ``animation.mp4``
    if ffmpeg is available; returns the paths written.

    ``fps`` is the playback frame rate, ``max_frames`` caps the number of frames (spread
    evenly over the run), ``speed`` the playback speed in simulated seconds per second
    (None: real time, or faster if needed to stay within ``max_frames``; see
    :func:`frame_plan`). ``on_frame(done, total)`` is called after each frame is drawn;
    ``run`` is the folder's contents if already loaded (:func:`load_run`).
    """
    run_dir = Path(run_dir)
    if run is None:
        run = load_run(run_dir)
    idx, real_speed = frame_plan(run.series["t"], fps, max_frames, speed)
    scene = _Scene(run)
    gif = run_dir / "animation.gif"
    mp4 = run_dir / "animation.mp4"
    ffmpeg = shutil.which("ffmpeg")
    proc: subprocess.Popen[bytes] | None = None
    if ffmpeg:
        size = scene.canvas.get_width_height()
        proc = subprocess.Popen(_ffmpeg_command(ffmpeg, size, fps, mp4),
                                stdin=subprocess.PIPE, stderr=subprocess.PIPE)

    scene.set_palette(scene.draw(int(idx[0]), real_speed), scene.draw(int(idx[-1]), real_speed))

    def frames() -> Iterator[Image.Image]:
        nonlocal proc
        for i, k in enumerate(idx):
            img = scene.draw(int(k), real_speed)
            if on_frame is not None:
                on_frame(i + 1, len(idx))
            if proc is not None:
                try:
                    proc.stdin.write(img.tobytes())  # type: ignore[union-attr]
                except (BrokenPipeError, OSError):
                    proc = _give_up_mp4(proc, mp4)
            yield scene.indexed(img)

    durations = [round(1000 / fps)] * len(idx)
    durations[-1] = max(durations[-1], round(1000 * _END_HOLD_S))
    try:
        it = frames()
        first = next(it)
        first.save(gif, save_all=True, append_images=it, duration=durations, loop=0)
    except BaseException:
        if proc is not None:
            proc.kill()
            proc.wait()
            mp4.unlink(missing_ok=True)
        raise
    written = [gif]
    if proc is not None:
        proc.stdin.close()  # type: ignore[union-attr]
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        if proc.wait() == 0 and mp4.is_file():
            written.append(mp4)
        else:
            warnings.warn(f"ffmpeg failed, no {mp4.name}: {err.strip()[-300:]}",
                          RuntimeWarning, stacklevel=2)
            mp4.unlink(missing_ok=True)
    return written


def _give_up_mp4(proc: subprocess.Popen[bytes], mp4: Path) -> None:
    """Stop a failed ffmpeg and remove its partial output."""
    err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    proc.kill()
    proc.wait()
    mp4.unlink(missing_ok=True)
    warnings.warn(f"ffmpeg failed, no {mp4.name}: {err.strip()[-300:]}", RuntimeWarning,
                  stacklevel=3)
    return None


def main(argv: list[str] | None = None) -> int:
    """``python -m tuav_sitl.animation RUN_DIR [--fps N] [--max-frames N] [--speed X]``."""
    import argparse
    import time

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_dir", type=Path)
    p.add_argument("--fps", type=int, default=FPS)
    p.add_argument("--max-frames", type=int, default=MAX_FRAMES)
    p.add_argument("--speed", type=float, default=None)
    a = p.parse_args(argv)
    t0 = time.perf_counter()
    for path in make_animation(a.run_dir, a.fps, a.max_frames, a.speed):
        print(path)
    print(f"{time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
