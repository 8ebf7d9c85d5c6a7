"""Traced programs kept on disk beside JAX's persistent compilation cache.

JAX's persistent cache keeps the compiled executable, but every process still traces and lowers
the Python function to find the cache key: on ACTIVSg2000, 4 s per .dyr playback program, 43 s
of a warm `jaxdse fleet` run's 127 s. :func:`call` exports the traced program once
(``jax.export``: serialized StableHLO) under a key of everything that determines it (the
function's name, jaxdse's source, JAX's version and backend, the arguments' structure, their
static values and the shapes and dtypes of their arrays); a later process loads it and goes
straight to the (cached) compilation.

Without a compilation cache folder (``jax_compilation_cache_dir``: `jaxdse` sets one, a library
caller may not), or where a program cannot be exported, the function runs under
``eqx.filter_jit`` as before: the results are the same either way.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax
from jax import export

from .waits import executing

FOLDER = "jaxdse_exported"
"""Subfolder of the compilation cache folder that holds the exported programs."""

_LOCK = threading.Lock()
_BUILDING: dict = {}
_LOADED: dict[str, export.Exported] = {}
_JITTED: dict[Callable, Callable] = {}
_COMPILED: dict = {}
_SOURCE: list[str] = []


def _source_digest() -> str:
    """SHA-256 of jaxdse's source files: a changed module is a new program."""
    if not _SOURCE:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parents[1]
        for path in sorted(root.rglob("*.py")):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
        _SOURCE.append(h.hexdigest())
    return _SOURCE[0]


def _folder() -> str | None:
    """The folder of the exported programs: ``FOLDER`` in JAX's compilation cache folder."""
    where = jax.config.jax_compilation_cache_dir
    return os.path.join(where, FOLDER) if where else None


def _key(name: str, treedef, static, leaves) -> str:
    static_leaves = jax.tree_util.tree_leaves(static)
    parts = (name, _source_digest(), jax.__version__, jax.default_backend(),
             bool(jax.config.jax_enable_x64), str(treedef), str(jax.tree_util.tree_structure(static)),
             [repr(x) for x in static_leaves], [(tuple(x.shape), str(x.dtype)) for x in leaves])
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:32]


def call(name: str, fn: Callable, *args):
    """``fn(*args)`` for a pure ``fn`` whose result is a tuple of arrays, from its exported
    program where the compilation cache folder holds (or can take) it."""
    where = _folder()
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    if where:
        try:
            program = _program(Path(where), name, fn, treedef, static, leaves)
        except Exception:   # noqa: BLE001 - a program export cannot take: traced as before
            program = None
        if program is not None:
            compiled = _compiled(("exported", id(program), treedef), lambda: jax.jit(program.call), leaves)
            executing()   # compiled: a bounded wait's run limit starts now (jaxdse._many.waits)
            return tuple(compiled(*leaves))
    with _LOCK:
        jitted = _JITTED.setdefault(fn, eqx.filter_jit(fn))
    compiled = jitted.lower(*args).compile()
    executing()
    return tuple(compiled(*args))


def _once(cache: dict, key, build: Callable):
    """``cache[key]``, built by ``build()`` once: a thread that asks for a key another thread is
    building waits for it (calls of one program side by side, e.g. the chunks of one model
    structure, trace and compile it once)."""
    with _LOCK:
        if key in cache:
            return cache[key]
        lock = _BUILDING.setdefault(key, threading.Lock())
    with lock:
        with _LOCK:
            if key in cache:
                return cache[key]
        value = build()
        with _LOCK:
            cache[key] = value
            _BUILDING.pop(key, None)
        return value


def _compiled(key, make: Callable, leaves):
    """The compiled executable of ``make()`` for these arrays' shapes (kept per key and shapes)."""
    key = (key, tuple((tuple(x.shape), str(x.dtype)) for x in leaves))
    return _once(_COMPILED, key, lambda: make().lower(*leaves).compile())


def _program(folder: Path, name: str, fn: Callable, treedef, static, leaves) -> export.Exported:
    key = _key(name, treedef, static, leaves)
    return _once(_LOADED, key, lambda: _load_or_export(folder, name, key, fn, treedef, static, leaves))


def _load_or_export(folder: Path, name: str, key: str, fn: Callable, treedef, static, leaves):
    path = folder / f"{name}-{key}.stablehlo"
    if path.exists():
        program = export.deserialize(bytearray(path.read_bytes()))
    else:
        def flat(*xs):
            return tuple(fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, xs), static)))

        flat.__name__ = flat.__qualname__ = name   # the program's name in JAX's logs

        program = export.export(jax.jit(flat))(*(jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves))
        data = program.serialize()   # (before the file: a program that cannot take leaves none)
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)   # as JAX's cache entries (mkstemp makes it private)
        os.replace(tmp, path)
    return program


__all__ = ["call"]
