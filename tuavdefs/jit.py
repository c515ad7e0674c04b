"""numba's ``njit`` for the project's scalar kernels, or the plain function without numba.

The kernels (the plant's model in ``sitl``, the control laws in ``companion`` and
``groundstation``) are written in scalar Python that numba compiles unchanged, so there is
one source for each whichever way it runs. ``TUAV_NO_JIT=1`` runs them as plain Python
(for debugging and coverage); compiled code is cached next to the sources.

numba keys its on-disk cache on the source file of the function it compiles, so on its own
it would keep serving a kernel compiled against an old version of a kernel it calls from
another module (or of a constant it reads from one). The cache here adds to the key a
digest of everything a kernel takes from outside its own file: the code and constants of
the compiled functions it calls, recursively, and the values of the global constants it
reads (:func:`dependency_digest`). Editing a law in one module therefore recompiles every
kernel that uses it, wherever that lives.

``TUAV_JIT_INTERPRET=sitl,companion`` (top-level packages, comma separated) leaves those
packages' kernels interpreted and compiles the rest: the cold-cache warm-up
(:mod:`tuav_sitl.warmup`) compiles the plant's kernels in one process and the controllers'
in another at the same time. :data:`JIT` is then False (not everything is compiled, so no
caller may count on a kernel being machine code). :func:`is_cached` says whether a kernel
would load from the cache, :func:`on_compile` reports each compilation as it ends.
"""

from __future__ import annotations

import hashlib
import os
import time
import types
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

#: Top-level packages whose kernels stay interpreted in this process (a warm-up process).
INTERPRETED: frozenset[str] = frozenset(
    p.strip() for p in os.environ.get("TUAV_JIT_INTERPRET", "").split(",") if p.strip())

try:
    if os.environ.get("TUAV_NO_JIT") == "1":
        raise ImportError("TUAV_NO_JIT=1")
    from numba import njit as _njit

    JIT = not INTERPRETED
except ImportError:  # numba absent or disabled: the same code, interpreted
    _njit = None
    JIT = False

_CONSTANT_TYPES = (bool, int, float, complex, str, bytes, tuple, type(None))


def _is_compiled(value: object) -> bool:
    """Whether ``value`` is a numba dispatcher (a compiled function)."""
    return isinstance(getattr(value, "py_func", None), types.FunctionType) and hasattr(
        value, "signatures")


def _names(code: types.CodeType) -> set[str]:
    """The global and attribute names ``code`` and the code nested in it use."""
    names = set(code.co_names)
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            names |= _names(c)
    return names


def _code_text(code: types.CodeType) -> list[Any]:
    """Bytecode and constants of ``code`` and the code nested in it."""
    out: list[Any] = [code.co_code]
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            out.extend(_code_text(c))
        elif isinstance(c, frozenset):  # iteration order varies between processes
            out.append(sorted(repr(x) for x in c))
        else:
            out.append(repr(c))
    return out


def _describe(fn: types.FunctionType, seen: set[int], out: list[Any]) -> None:
    names = _names(fn.__code__)
    for name in sorted(names):
        if name not in fn.__globals__:
            continue
        value = fn.__globals__[name]
        if isinstance(value, types.ModuleType):
            # compiled functions reached as module attributes: module.kernel(...)
            for attr in sorted(names):
                sub = getattr(value, attr, None)
                if _is_compiled(sub):
                    _describe_value(f"{name}.{attr}", sub, seen, out)
            continue
        _describe_value(name, value, seen, out)


def _describe_value(name: str, value: Any, seen: set[int], out: list[Any]) -> None:
    if _is_compiled(value):
        py = value.py_func
        if id(py) in seen:
            return
        seen.add(id(py))
        out.append((name, py.__module__, py.__qualname__, _code_text(py.__code__)))
        _describe(py, seen, out)
    elif isinstance(value, _CONSTANT_TYPES):
        out.append((name, repr(value)))
    elif hasattr(value, "tobytes") and hasattr(value, "dtype"):  # a numpy array constant
        out.append((name, str(value.dtype), getattr(value, "shape", ()), value.tobytes()))


def dependency_digest(fn: Callable[..., Any]) -> str:
    """A digest of what the compiled ``fn`` takes from outside its own code: the code and
    constants of the compiled functions it calls (recursively) and the values of the
    global constants it or they read (numba freezes those into the machine code)."""
    py = getattr(fn, "py_func", fn)
    out: list[Any] = []
    _describe(py, {id(py)}, out)
    return hashlib.sha256(repr(out).encode()).hexdigest()


_DependencyCache: Any = None
if _njit is not None:
    try:
        from numba.core.caching import FunctionCache

        class _DependencyCache(FunctionCache):  # type: ignore[no-redef]
            """numba's function cache, its index key extended by the function's
            :func:`dependency_digest`."""

            def _index_key(self, sig: Any, codegen: Any) -> tuple[Any, ...]:
                key = super()._index_key(sig, codegen)
                return (*key, dependency_digest(self._py_func))

    except (ImportError, AttributeError):  # numba's internals moved: its plain cache
        _DependencyCache = None


def njit(fn: F) -> F:
    """Compile ``fn`` in nopython mode with an on-disk cache (identity without numba, or
    when its package is in :data:`INTERPRETED`)."""
    if _njit is None or fn.__module__.partition(".")[0] in INTERPRETED:
        return fn
    dispatcher = _njit(cache=True)(fn)
    if _DependencyCache is not None and hasattr(dispatcher, "_cache"):
        dispatcher._cache = _DependencyCache(fn)
    return dispatcher  # type: ignore[no-any-return]


def entry_point(kernel: F, *example_args: Any) -> F:
    """The machine code of the compiled ``kernel`` for the types of ``example_args``
    (loaded from the cache, or compiled, now), as a callable that skips numba's dispatch.

    Calling a numba function resolves the types of all its arguments and looks the
    specialisation up at every call: about 30 ns an argument, a microsecond for a kernel
    of fifty. A call site whose argument types never change can call the specialisation
    directly. numba still converts each argument to its declared type (a number to the
    float, int or bool it stands for), but checks little else: an array of another dtype
    or rank there would be undefined behaviour, so use this only where the arrays are the
    caller's own. Without numba (or if numba's internals moved) ``kernel`` itself.
    """
    if _njit is None:
        return kernel
    try:
        from numba.core.typing.typeof import Purpose, typeof

        sig = tuple(typeof(a, Purpose.argument) for a in example_args)
        return kernel.compile(sig)  # type: ignore[attr-defined, no-any-return]
    except Exception:  # noqa: BLE001 - any failure: the plain dispatcher still works
        return kernel


def is_cached(kernel: Callable[..., Any]) -> bool:
    """Whether the compiled ``kernel`` has machine code in the on-disk cache for its current
    source and dependencies (for some argument types), i.e. would load rather than compile.
    True for a plain function (nothing to compile)."""
    cache = getattr(kernel, "_cache", None)
    if not _is_compiled(kernel) or cache is None:
        return True
    if getattr(kernel, "signatures", None):
        return True   # already loaded (or compiled) in this process
    try:
        index = cache._cache_file._load_index()   # {} when the source changed since
    except Exception:  # noqa: BLE001 - numba's internals moved: assume it must compile
        return False
    digest = dependency_digest(kernel)
    return any(isinstance(k, tuple) and k and k[-1] == digest for k in index)


def on_compile(callback: Callable[[str, float], None]) -> Callable[[], None]:
    """Call ``callback(name, seconds)`` each time numba finishes compiling a kernel in this
    process (``name`` is ``module.function``; a kernel loaded from the cache is not
    reported). Returns the function that stops the reports. Without numba, nothing."""
    if _njit is None:
        return lambda: None
    from numba.core import event

    class _Listener(event.Listener):
        def __init__(self) -> None:
            self.started: list[float] = []

        def on_start(self, ev: Any) -> None:
            self.started.append(time.perf_counter())

        def on_end(self, ev: Any) -> None:
            t0 = self.started.pop() if self.started else time.perf_counter()
            d = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            py = getattr(d, "py_func", None)
            name = f"{py.__module__}.{py.__qualname__}" if py is not None else "kernel"
            callback(name, time.perf_counter() - t0)

    listener = _Listener()
    event.register("numba:compile", listener)
    return lambda: event.unregister("numba:compile", listener)
