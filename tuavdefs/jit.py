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
"""

from __future__ import annotations

import hashlib
import os
import types
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

try:
    if os.environ.get("TUAV_NO_JIT") == "1":
        raise ImportError("TUAV_NO_JIT=1")
    from numba import njit as _njit

    JIT = True
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
    """Compile ``fn`` in nopython mode with an on-disk cache (identity without numba)."""
    if _njit is None:
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
