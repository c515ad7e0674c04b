"""A run folder's figures and animation, drawn on the machine's cores with progress shown.

:func:`draw_run` is what ``tuav-sitl run``, ``plot`` and ``results`` call after the
simulation: the animation's frames are drawn in this process while forked worker processes
draw the figures, one figure a task; once the animation is done this process takes the
figures no worker has started. The figures and frames are those of
:func:`tuav_sitl.figures.make_figures` and :func:`tuav_sitl.animation.make_animation`, only
their order in time differs. :class:`DrawProgress` is the one line of progress on stderr
(figures done, animation frames done, elapsed time).
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import current_process, get_context
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from tuav_sitl.figures import RunData

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


#: The run folder being drawn, loaded once before the workers fork (they inherit it).
_RUN: tuple[str, RunData] | None = None


def _figure(run_dir: str, name: str) -> list[Path]:
    from tuav_sitl.figures import build_figures, load_run, save_figures

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


def draw_run(run_dir: Path, figures: bool = True, animation: bool = True,
             progress: TextIO | None = None, workers: int | None = None) -> DrawResult:
    """Draw the figures and (``animation``) the animation of the run folder ``run_dir``.

    ``workers`` is the number of processes forked for the figures (default: the cores but
    one; 0 draws everything here, one after the other). Progress goes to ``progress``.
    """
    from tuav_sitl.figures import FIGURE_NAMES, load_run, missing_series

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
    bar = DrawProgress(progress, len(names), None if not animation else 0)
    bar.show(force=True)
    n_workers = min(_workers(workers), len(names))
    done: dict[str, list[Path]] = {}
    pool = (ProcessPoolExecutor(n_workers, mp_context=get_context("fork"))
            if n_workers > 0 else None)
    try:
        futures: dict[str, Future[list[Path]]] = {}
        if pool is not None:
            for name in names:
                fut = pool.submit(_figure, str(run_dir), name)
                fut.add_done_callback(lambda f: None if f.cancelled() else bar.figure_done())
                futures[name] = fut
        if animation:
            from tuav_sitl.animation import make_animation

            out.animation = make_animation(run_dir, on_frame=bar.frame_done, run=run)
        # what no worker has started is drawn here, from the back of the queue (the
        # workers take from the front)
        for name in reversed(names):
            fut = futures.get(name)
            if fut is None or fut.cancel():
                done[name] = _figure(str(run_dir), name)
                bar.figure_done()
        for name, fut in futures.items():
            if name not in done:
                done[name] = fut.result()
    finally:
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        bar.close()
        _RUN = None
    out.figures = [p for name in names for p in done[name]]
    return out
