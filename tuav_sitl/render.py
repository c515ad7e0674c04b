"""A run folder's figures and animation, drawn on the machine's cores with progress shown.

:func:`draw_run` is what ``tuav-sitl run``, ``plot`` and ``results`` call after the
simulation: the animation's frames are drawn in this process while forked worker processes
draw the figures, one figure a task; once the animation is done this process takes the
figures no worker has started. ``tuav-sitl run`` forks a :class:`DrawPool` before the
simulation instead: its workers import the drawing libraries on the other cores while the
simulation runs, and afterwards draw the animation and the figures, this process only
showing their progress. The figures and frames are those of
:func:`tuav_sitl.figures.make_figures` and :func:`tuav_sitl.animation.make_animation`, only
their order in time differs. :class:`DrawProgress` is the one line of progress on stderr
(figures done, animation frames done, elapsed time).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from multiprocessing import current_process, get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from tuav_sitl.figures import RunData

__all__ = ["DrawPool", "DrawProgress", "DrawResult", "draw_run"]


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


#: In a :class:`DrawPool` worker: where the animation's frame counts go.
_FRAMES: Any = None


def _warm(frames: Any) -> None:
    """A :class:`DrawPool` worker's start: import what drawing needs (the slow part of a
    first figure) and keep the queue the animation reports its frames on."""
    global _FRAMES
    _FRAMES = frames
    import matplotlib

    matplotlib.use("Agg")
    import tuav_sitl.animation
    import tuav_sitl.figures  # noqa: F401


def _ready() -> bool:
    return True


def _animate(run_dir: str) -> list[Path]:
    from tuav_sitl.animation import make_animation

    def on_frame(done: int, total: int) -> None:
        if _FRAMES is not None:
            _FRAMES.put((done, total))

    return make_animation(Path(run_dir), on_frame=on_frame)


class DrawPool:
    """Worker processes forked before a simulation to draw its run folder afterwards
    (:func:`draw_run`'s ``pool``): one per core, each importing the drawing libraries at
    once, so that this happens on the cores the simulation leaves idle.

    A context manager; :attr:`pool` is None where no worker can be forked (inside a
    daemonic process), and :func:`draw_run` then draws in this process as without one.
    """

    def __init__(self, workers: int | None = None) -> None:
        self.pool: ProcessPoolExecutor | None = None
        self.frames: Any = None
        n = (0 if current_process().daemon else
             max(1, os.cpu_count() or 1) if workers is None else max(0, workers))
        if n == 0:
            return
        ctx = get_context("fork")
        self.frames = ctx.Queue()
        self.pool = ProcessPoolExecutor(n, mp_context=ctx, initializer=_warm,
                                        initargs=(self.frames,))
        self.pool.submit(_ready)          # forks every worker now (the fork context's rule)

    def __enter__(self) -> DrawPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (what they have not started is cancelled)."""
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None
        if self.frames is not None:
            self.frames.close()
            self.frames.join_thread()
            self.frames = None


def _draw_in_pool(pool: DrawPool, run_dir: Path, names: list[str], animation: bool,
                  bar: DrawProgress, out: DrawResult) -> dict[str, list[Path]]:
    """Draw the animation (first, being the longest) and the figures on ``pool``'s
    workers, showing their progress here; the figures' paths by name."""
    assert pool.pool is not None
    anim = pool.pool.submit(_animate, str(run_dir)) if animation else None
    futures = {name: pool.pool.submit(_figure, str(run_dir), name) for name in names}
    for fut in futures.values():
        fut.add_done_callback(lambda f: None if f.cancelled() else bar.figure_done())
    pending: set[Future[list[Path]]] = set(futures.values())
    if anim is not None:
        pending.add(anim)
    while pending:
        _, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
        while True:
            try:
                done, total = pool.frames.get_nowait()
            except queue.Empty:
                break
            bar.frame_done(done, total)
    if anim is not None:
        out.animation = anim.result()
    return {name: fut.result() for name, fut in futures.items()}


def _workers(requested: int | None) -> int:
    """Worker processes to fork: ``requested``, else one less than the cores; none inside
    a daemonic process (a pool's worker cannot have children)."""
    if current_process().daemon:
        return 0
    if requested is not None:
        return max(0, requested)
    return max(0, (os.cpu_count() or 1) - 1)


def draw_run(run_dir: Path, figures: bool = True, animation: bool = True,
             progress: TextIO | None = None, workers: int | None = None,
             pool: DrawPool | None = None) -> DrawResult:
    """Draw the figures and (``animation``) the animation of the run folder ``run_dir``.

    ``workers`` is the number of processes forked for the figures (default: the cores but
    one; 0 draws everything here, one after the other); with a ``pool`` (forked earlier,
    its workers warm) its workers draw everything instead. Progress goes to ``progress``.
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
    if pool is not None and pool.pool is not None:
        try:
            done_in_pool = _draw_in_pool(pool, run_dir, names, animation, bar, out)
        finally:
            bar.close()
            _RUN = None
        out.figures = [p for name in names for p in done_in_pool[name]]
        return out
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
