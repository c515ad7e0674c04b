"""A run folder's figures and animation, drawn on the machine's cores with progress shown.

:func:`draw_run` is what ``tuav-sitl run``, ``plot`` and ``results`` call after the
simulation: the animation's frames are drawn in this process while forked worker processes
draw the figures, each taking the next figure when it is free (the dearest first); once the
animation is done this process takes figures from the same queue. The figures and frames
are those of :func:`tuav_sitl.figures.make_figures` and
:func:`tuav_sitl.animation.make_animation`, only their order in time differs.
:class:`DrawProgress` is the one line of progress on stderr (figures done, animation
frames done, elapsed time).
"""

from __future__ import annotations

import os
import threading
import time
import traceback
from dataclasses import dataclass, field
from multiprocessing import current_process, get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from tuav_sitl.run_data import RunData

__all__ = ["DrawProgress", "DrawResult", "draw_run"]


class DrawProgress:
    """One throttled line on ``stream`` saying how far the figures and the animation are."""

    def __init__(self, stream: TextIO | None, figures: int, frames: int | None,
                 width: int = 20) -> None:
        self.stream = stream
        self.figures_total = figures
        self.figures_done = 0
        self.frames_total = frames
        self.frames_done = 0
        self.width = width
        self._start = time.perf_counter()
        self._last = -1.0
        self._shown = False
        # figures are reported from the worker pool's thread, frames from this one
        self._lock = threading.Lock()

    def figure_done(self) -> None:
        """One more figure written."""
        with self._lock:
            self.figures_done += 1
        self.show(force=True)

    def frame_done(self, done: int, total: int) -> None:
        """``done`` of the animation's ``total`` frames drawn."""
        self.frames_done, self.frames_total = done, total
        self.show(force=done == total)

    def show(self, force: bool = False) -> None:
        """Redraw the line (at most 5 times a second unless ``force``)."""
        if self.stream is None:
            return
        with self._lock:
            self._show(force)

    def _show(self, force: bool) -> None:
        assert self.stream is not None
        now = time.perf_counter()
        if not force and now - self._last < 0.2:
            return
        self._last = now
        self._shown = True
        parts = []
        work = done = 0.0
        if self.figures_total:
            parts.append(f"figures {self.figures_done}/{self.figures_total}")
            work += 1.0
            done += self.figures_done / self.figures_total
        if self.frames_total:
            parts.append(f"animation frames {self.frames_done}/{self.frames_total}")
            work += 1.0
            done += self.frames_done / self.frames_total
        frac = done / work if work else 1.0
        filled = int(frac * self.width)
        self.stream.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] drawing: "
                          + ", ".join(parts) + f", {now - self._start:5.1f} s elapsed ")
        self.stream.flush()

    def close(self) -> None:
        """End the line."""
        with self._lock:
            if self.stream is not None and self._shown:
                self.stream.write("\n")
                self.stream.flush()
                self._shown = False


@dataclass
class DrawResult:
    """What :func:`draw_run` wrote."""

    figures: list[Path] = field(default_factory=list)
    """The figures' PNG files, in :data:`tuav_sitl.figures.FIGURE_NAMES` order."""
    animation: list[Path] = field(default_factory=list)
    """``animation.gif`` (and ``animation.mp4`` when ffmpeg is there)."""
    skipped: list[str] = field(default_factory=list)
    """A note for each figure the run lacks the data of."""


#: The figures from the dearest to draw to the cheapest (CPU time on the circle, most of it
#: the layout and the text): the drawers take them in this order, so that the last to be
#: taken, which decide when drawing ends, are short.
DRAW_ORDER = ("snapshots", "states", "estimate", "lyapunov", "path_3d", "errors",
              "attitude_tracking", "tension_and_winder", "position_tracking",
              "tether_length")

#: The run folder being drawn, loaded once before the workers fork (they inherit it).
_RUN: tuple[str, RunData] | None = None


def _figure(run_dir: str, name: str) -> list[Path]:
    from tuav_sitl.figures import build_figures, save_figures
    from tuav_sitl.run_data import load_run

    run = _RUN[1] if _RUN is not None and _RUN[0] == run_dir else load_run(Path(run_dir))
    return save_figures(build_figures(run.series, run.scenario, [name], run.metrics),
                        Path(run_dir) / "figures")


def _workers(requested: int | None) -> int:
    """Worker processes to fork: ``requested``, else one less than the cores; none inside
    a daemonic process (a pool's worker cannot have children)."""
    if current_process().daemon:
        return 0
    if requested is not None:
        return max(0, requested)
    return max(0, (os.cpu_count() or 1) - 1)


class _Queue:
    """The figures still to draw, shared by this process and its forked workers: each
    drawer takes the next one when it is free (so the work balances itself whatever each
    figure costs), and a worker sends back the files it wrote, or its error."""

    def __init__(self, names: list[str]) -> None:
        ctx = get_context("fork")
        self.names = names
        self._next = ctx.Value("i", 0)
        self.results: Any = ctx.SimpleQueue()

    def take(self) -> int | None:
        """The index of the next figure to draw, None when all are taken."""
        with self._next.get_lock():
            i = int(self._next.value)
            if i >= len(self.names):
                return None
            self._next.value = i + 1
            return i

    def drain(self, run_dir: str) -> None:
        """A worker's life: draw figures until none is left."""
        while (i := self.take()) is not None:
            try:
                paths: list[Path] | str = _figure(run_dir, self.names[i])
            except BaseException:  # noqa: BLE001 - the error travels to the main process
                paths = traceback.format_exc()
            self.results.put((i, paths))


def _worker_main(queue: _Queue, run_dir: str) -> None:
    try:
        queue.drain(run_dir)
    finally:
        os._exit(0)   # a forked child: none of the parent's exit handlers


def draw_run(run_dir: Path, figures: bool = True, animation: bool = True,
             progress: TextIO | None = None, workers: int | None = None) -> DrawResult:
    """Draw the figures and (``animation``) the animation of the run folder ``run_dir``.

    ``workers`` is the number of processes forked for the figures (default: the cores but
    one; 0 draws everything here, one after the other); this process joins them once the
    animation is drawn. Progress goes to ``progress``.
    """
    from tuav_sitl.figures import FIGURE_NAMES, missing_series
    from tuav_sitl.run_data import load_run

    global _RUN
    run_dir = Path(run_dir)
    out = DrawResult()
    run = load_run(run_dir)
    _RUN = (str(run_dir), run)
    names: list[str] = []
    if figures:
        for name in FIGURE_NAMES:
            lacking = missing_series(run.series, name)
            if lacking:
                out.skipped.append(f"{name}: the run has no {', '.join(lacking)}")
            else:
                names.append(name)
    order = sorted(names, key=lambda n: DRAW_ORDER.index(n) if n in DRAW_ORDER
                   else len(DRAW_ORDER))
    bar = DrawProgress(progress, len(names), None if not animation else 0)
    bar.show(force=True)
    queue = _Queue(order)
    done: dict[int, list[Path]] = {}
    procs = []
    collector = None
    try:
        for _ in range(min(_workers(workers), len(order))):
            proc = get_context("fork").Process(target=_worker_main,
                                               args=(queue, str(run_dir)), daemon=True)
            proc.start()
            procs.append(proc)
        errors: list[str] = []
        if procs:
            def collect() -> None:
                # the workers' results as they come (the progress line counts them while
                # this process draws the animation); a None ends it
                while (item := queue.results.get()) is not None:
                    i, paths = item
                    if isinstance(paths, str):
                        errors.append(paths)
                    else:
                        done[i] = paths
                    bar.figure_done()

            collector = threading.Thread(target=collect, daemon=True)
            collector.start()
        if animation:
            from tuav_sitl.animation import make_animation

            out.animation = make_animation(run_dir, on_frame=bar.frame_done, run=run)
        while (i := queue.take()) is not None:
            done[i] = _figure(str(run_dir), order[i])
            bar.figure_done()
        for proc in procs:
            proc.join()
        if collector is not None:
            queue.results.put(None)
            collector.join()
        if errors:
            raise RuntimeError("drawing a figure failed in a worker:\n" + errors[0])
        # a worker that died (killed) leaves its figure undrawn: drawn here
        for i, name in enumerate(order):
            if i not in done:
                done[i] = _figure(str(run_dir), name)
                bar.figure_done()
    finally:
        for proc in procs:
            if proc.is_alive():
                proc.kill()
                proc.join()
        bar.close()
        _RUN = None
    by_name = {order[i]: paths for i, paths in done.items()}
    out.figures = [p for name in names for p in by_name[name]]
    return out
