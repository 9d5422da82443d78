"""The system's C compiler, a disk cache of shared libraries keyed by their source, and a traced program called from
Python through ctypes (docs/native.md).

The compiler is `$CC` where set, else `cc`; a library is built once per distinct source and compiler
(`$ROBOTADAPT_CACHE/c/<sha256>.so`, default `~/.cache/robotadapt/c`), written under a temporary name and renamed, so
two processes never load half a file and a second process loads what the first built.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import pickle
import shlex
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from ..tracing import float64, jax_module
from ..validation import ConfigError
from .c99 import c_type, translate
from .patience import Building, patient

# -O2 without the passes that grow superlinearly on one long function (partial redundancy elimination, value range
# propagation, global CSE): the Panda's RK4 chunk (28 000 lines) builds in 32 s instead of 94 s
CFLAGS = ("-O2", "-fno-tree-pre", "-fno-tree-vrp", "-fno-gcse", "-fno-thread-jumps", "-std=c99", "-fPIC", "-shared")
PRELUDE = "#include <math.h>\n#include <stdint.h>\n#include <stddef.h>\n#include <string.h>\n\n"
#: a translated program longer than this (lines) is built by a compiler process of its own where the caller need not
#: wait (`patience(False)`): an n-DOF arm's loop, for which gcc takes 10–60 s (the two-link arm's: 800 lines, 1 s)
BACKGROUND_LINES = 5000
STALE = 900.0  # s after which a background build's marker is taken for one whose process died
INSTALL = "install one (Debian/Ubuntu: apt-get install gcc; macOS: xcode-select --install) or point CC at it"


def compiler() -> str | None:
    """The C compiler's path: `$CC` (a name on PATH or a path), else `cc`; None when there is none."""
    return _which((os.environ.get("CC", "").strip() or "cc").split()[0], os.environ.get("PATH", os.defpath))


@cache
def _which(name: str, path: str) -> str | None:
    """`shutil.which`, once per name and PATH (a sweep asks at every run)."""
    return shutil.which(name, path=path)


def require_compiler(field: str) -> str:
    """The compiler, or a ConfigError naming `field` and how to install one."""
    found = compiler()
    if found is None:
        raise ConfigError(field, f"no C compiler ({os.environ.get('CC', 'cc')!r} not found): {INSTALL}")
    return found


def cache_dir() -> Path:
    return Path(os.environ.get("ROBOTADAPT_CACHE", Path.home() / ".cache" / "robotadapt")) / "c"


@dataclass(frozen=True)
class Later:
    """A program whose library a compiler process is building: what loads it once built."""

    path: Path
    name: str
    ins: list[tuple[tuple[int, ...], Any]]
    outs: list[tuple[tuple[int, ...], Any]]

    def load(self) -> Compiled | None:
        """The program, or None while its library is not there yet."""
        return Compiled(self.path, self.name, self.ins, self.outs) if self.path.exists() else None


def shared_library(source: str, field: str = "simulation.backend") -> Path:
    """The shared library of the C `source`, compiled once per source and compiler (module docstring); built in the
    background (:class:`Building` raised) for a long source within `patience(False)`."""
    cc = require_compiler(field)
    key = hashlib.sha256("\0".join([cc, *CFLAGS, source]).encode()).hexdigest()[:32]
    folder = cache_dir()
    path = folder / f"{key}.so"
    if path.exists():
        return path
    folder.mkdir(parents=True, exist_ok=True)
    if not patient() and source.count("\n") > BACKGROUND_LINES:
        _build_later(cc, source, path)
        raise Building(field, f"its C program ({source.count(chr(10))} lines) is being built in the background", path)
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        c_file, so_file = Path(tmp) / "program.c", Path(tmp) / "program.so"
        c_file.write_text(source, encoding="utf-8")
        done = subprocess.run([cc, *CFLAGS, "-o", str(so_file), str(c_file), "-lm"], capture_output=True, text=True)
        if done.returncode != 0:
            first = (done.stderr.strip().splitlines() or ["(no message)"])[0]
            raise ConfigError(field, f"the C compiler {cc} failed on the translated program: {first}")
        os.replace(so_file, path)
    return path


def _build_later(cc: str, source: str, path: Path) -> None:
    """Start a compiler process of its own (it outlives this one) that writes the library to `path` whole (built
    under a temporary name, renamed); none when one is under way for it (its marker younger than `STALE` s)."""
    marker = path.with_suffix(".building")
    try:
        os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        if time.time() - marker.stat().st_mtime < STALE:
            return
        marker.unlink(missing_ok=True)  # a build that never ended (its process killed): started again next time
        return
    tmp = Path(tempfile.mkdtemp(dir=path.parent))
    (tmp / "program.c").write_text(source, encoding="utf-8")
    so = tmp / "program.so"
    command = " ".join(shlex.quote(a) for a in [cc, *CFLAGS, "-o", str(so), str(tmp / "program.c"), "-lm"])
    script = f"({command} && mv {shlex.quote(str(so))} {shlex.quote(str(path))}; rm -rf {shlex.quote(str(tmp))} " \
             f"{shlex.quote(str(marker))}) >/dev/null 2>&1 &"  # the shell returns at once, its child builds on
    subprocess.run(["sh", "-c", script], start_new_session=True, stdin=subprocess.DEVNULL, check=False)


def entry(name: str, n_in: int, n_out: int, types: Sequence[str]) -> str:
    """`void name(void **p)`: the translated `name_impl` called with its inputs and outputs from one pointer table."""
    args = [f"({'const ' if k < n_in else ''}{t} *)p[{k}]" for k, t in enumerate(types)]
    return f"void {name}(void **p) {{ {name}_impl({', '.join(args)}); }}\n"


@cache
def library(path: Path) -> Any:
    """The shared library at `path`, loaded once per process."""
    return ctypes.CDLL(str(path))


class Compiled:
    """A native function of arrays: `compiled(*arrays) -> list of arrays`, with the inputs and outputs (shape, dtype) of
    the traced program it was translated from. Each call allocates its outputs; the hot paths
    (:mod:`robotadapt.native.controller`) keep their own buffers."""

    def __init__(self, path: Path, name: str, ins: Sequence[tuple[tuple[int, ...], Any]],
                 outs: Sequence[tuple[tuple[int, ...], Any]]) -> None:
        self.path, self.name = path, name
        self.ins = [(tuple(s), np.dtype(d)) for s, d in ins]
        self.outs = [(tuple(s), np.dtype(d)) for s, d in outs]
        self._fn = getattr(library(path), name)
        self._fn.argtypes = [ctypes.POINTER(ctypes.c_void_p)]
        self._fn.restype = None

    @classmethod
    def translated(cls, closed: Any, name: str = "program", field: str = "simulation.backend",
                   zeros: Sequence[np.ndarray | None] = ()) -> Compiled:
        """A ClosedJaxpr translated to C (:func:`robotadapt.native.c99.translate`; `zeros`: the inputs' elements that
        are zero in every call) and built (:func:`shared_library`)."""
        jaxpr = closed.jaxpr
        ins = [(tuple(v.aval.shape), np.dtype(v.aval.dtype)) for v in jaxpr.invars]
        outs = [(tuple(v.aval.shape), np.dtype(v.aval.dtype)) for v in jaxpr.outvars]
        types = [c_type(d) for _, d in ins + outs]
        source = PRELUDE + translate(closed, f"{name}_impl", zeros=zeros) + entry(name, len(ins), len(outs), types)
        try:
            return cls(shared_library(source, field), name, ins, outs)
        except Building as building:
            building.later = Later(building.path, name, ins, outs)
            raise

    def __call__(self, *args: Any, out: Sequence[np.ndarray] | None = None) -> list[np.ndarray]:
        """The outputs, new arrays or written into `out` (C-contiguous arrays of the outputs' shapes and dtypes)."""
        ins = [np.ascontiguousarray(np.asarray(a, dtype=d).reshape(s)) for a, (s, d) in zip(args, self.ins, strict=True)]
        if out is None:
            outs = [np.empty(s, dtype=d) for s, d in self.outs]
        else:
            outs = list(out)
            if any(a.shape != s or a.dtype != d or not a.flags.c_contiguous
                   for a, (s, d) in zip(outs, self.outs, strict=True)):
                raise ValueError("out: C-contiguous arrays of the program's output shapes and dtypes")
        table = (ctypes.c_void_p * (len(ins) + len(outs)))(*[a.ctypes.data for a in ins + outs])
        self._fn(table)
        return outs


@cache
def fingerprint() -> str:
    """What a traced program depends on besides its own description: the package's source, JAX's and numpy's versions.
    A stored program (:func:`remember`) is found again only under the same fingerprint."""
    from importlib.metadata import PackageNotFoundError, version

    digest = hashlib.sha256()
    root = Path(__file__).resolve().parents[1]
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    for package in ("jax", "numpy"):
        try:
            digest.update(f"{package} {version(package)}".encode())
        except PackageNotFoundError:
            digest.update(package.encode())
    return digest.hexdigest()


def _index(key: str) -> Path:
    return cache_dir() / "programs" / f"{hashlib.sha256((fingerprint() + key).encode()).hexdigest()[:32]}.pkl"


def remembered(key: str) -> tuple[Compiled, Any] | None:
    """The program stored under `key` (a stable description of what was traced) and its stored companion (the layout
    of its outputs), loaded without JAX; None when there is none (or its library has gone)."""
    path = _index(key)
    try:
        with path.open("rb") as f:
            stored = pickle.load(f)
        return Compiled(cache_dir() / stored["library"], stored["name"], stored["ins"], stored["outs"]), stored["extra"]
    except (OSError, EOFError, pickle.UnpicklingError, KeyError, AttributeError, ImportError):
        return None


def remember(key: str, program: Compiled, extra: Any) -> None:
    """Store `program` under `key` with `extra`, written whole (a temporary file renamed), for :func:`remembered`."""
    path = _index(key)
    path.parent.mkdir(parents=True, exist_ok=True)
    stored = {"library": program.path.name, "name": program.name, "ins": [(s, d.str) for s, d in program.ins],
              "outs": [(s, d.str) for s, d in program.outs], "extra": extra}
    with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as f:
        pickle.dump(stored, f)
    os.replace(f.name, path)


@float64
def traced(fn: Callable[..., Any], *args: Any) -> tuple[Any, Any]:
    """The one trace of a program for C: (the ClosedJaxpr of `fn(*args)` in float64, the layout of its outputs: their
    tuples with each array's position among the program's outputs instead). `args` and the outputs are tuples (named
    or not) of arrays; anything else is refused with a ConfigError, for the translator takes flat lists of arrays."""
    jax = jax_module()
    closed = jax.make_jaxpr(fn)(*args)
    if len(closed.jaxpr.invars) != len(_arrays(args)):
        raise ConfigError("simulation.backend", "a compiled program's inputs hold more than tuples of arrays")
    count = iter(range(len(closed.jaxpr.outvars)))
    outputs = _layout(jax.eval_shape(fn, *args), count)
    if next(count, None) is not None:
        raise ConfigError("simulation.backend", "a compiled program's outputs hold more than tuples of arrays")
    return closed, outputs


_LATER: dict[Any, tuple[Later, Any]] = {}  # programs this process saw go to a background build, by their key


def compiled(fn: Callable[..., Any], *args: Any, name: str = "program", zeros: Sequence[np.ndarray | None] = (),
             key: Any = None) -> tuple[Compiled, Any]:
    """`fn(*args)` traced (:func:`traced`), translated to C and built: (the native program, its outputs' layout);
    `zeros`: the leading inputs' elements that are zero in every call (folded by the translator). `key` (hashable,
    what the program is): one this process sent to a background build is loaded once its library is there, or
    :class:`Building` raised again, without tracing it anew."""
    if key in _LATER:
        later, outputs = _LATER[key]
        program = later.load()
        if program is None:
            raise Building("simulation.backend", "its C program is being built in the background", later.path)
        del _LATER[key]
        return program, outputs
    closed, outputs = traced(fn, *args)
    try:
        return Compiled.translated(closed, name, zeros=zeros), outputs
    except Building as building:
        if key is not None and building.later is not None:
            _LATER[key] = (building.later, outputs)
        raise


def _arrays(tree: Any) -> list[Any]:
    """The arrays of nested tuples, in order (None holds none)."""
    if tree is None:
        return []
    return [a for part in tree for a in _arrays(part)] if isinstance(tree, tuple | list) else [tree]


def _layout(tree: Any, count: Any) -> Any:
    """`tree` (nested tuples, named or not) with each array replaced by the next number of `count` (None kept)."""
    if tree is None:
        return None
    if isinstance(tree, tuple | list):
        parts = [_layout(part, count) for part in tree]
        return type(tree)(*parts) if hasattr(tree, "_fields") else type(tree)(parts)
    return next(count)
