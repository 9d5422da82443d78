"""Jobs spread over the machine's cores by `fork`: `robotadapt run`'s figures, drawn at once by processes that inherit
the imports (matplotlib: a third of a fresh run) and the result, so that nothing is imported or sent twice.

Forked only where that is safe: on Linux, and with JAX not imported (its threads can deadlock a forked child; BLAS's
thread pool is shut down around a fork by its own handler). Elsewhere, and for one core, the jobs run one after the
other in this process, with the same results. A library call keeps one core unless asked: a notebook's kernel or a
server has threads of its own that a fork would not carry.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

T = TypeVar("T")
PATIENCE = 120.0  # s a forked process may stay silent once this one's jobs are done (a figure takes under one)


def forkable() -> bool:
    """Whether a fork of this process is safe: on Linux, before JAX is imported."""
    return sys.platform == "linux" and hasattr(os, "fork") and "jax" not in sys.modules


def groups(count: int, cores: int) -> list[range]:
    """The jobs' indices in `min(cores, count)` consecutive groups, as even as can be, the first the smallest: this
    process takes it (a caller lists its heaviest job first)."""
    parts = max(1, min(cores, count))
    sizes = sorted(count // parts + (k < count % parts) for k in range(parts))
    starts = [sum(sizes[:k]) for k in range(parts)]
    return [range(start, start + size) for start, size in zip(starts, sizes, strict=True)]


def spread(jobs: Sequence[Callable[[], T]], cores: int = 1) -> list[T]:
    """Each job's result, in order: the first group of jobs (:func:`groups`) in this process, each other group in a
    forked process, all at once. A job's exception is raised here (after every process ended), the first in order."""
    parts = groups(len(jobs), cores)
    if len(parts) < 2 or not forkable():
        return [job() for job in jobs]
    children = [_fork([jobs[i] for i in part]) for part in parts[1:]]
    try:
        mine: tuple[str, Any] = ("ok", [jobs[i]() for i in parts[0]])
    except BaseException as failed:  # noqa: BLE001 - raised below, once every child is reaped
        mine = ("error", failed)
    outcomes = [mine, *(_collect(pid, fd, [jobs[i] for i in part])
                        for (pid, fd), part in zip(children, parts[1:], strict=True))]
    for kind, value in outcomes:
        if kind == "error":
            raise value
    return [result for _, results in outcomes for result in results]


def _fork(jobs: list[Callable[[], Any]]) -> tuple[int, int]:
    """(pid, read end of its pipe) of a child that runs `jobs` and writes its pickled outcome to the pipe."""
    read, write = os.pipe()
    with warnings.catch_warnings():  # Python ≥ 3.12 warns of any thread at a fork; BLAS's are handled (docstring)
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid:
        os.close(write)
        return pid, read
    os.close(read)
    code = 1
    try:
        try:
            outcome: tuple[str, Any] = ("ok", [job() for job in jobs])
            code = 0
        except BaseException as failed:  # noqa: BLE001 - sent to the parent, which raises it
            outcome = ("error", failed)
        try:
            payload = pickle.dumps(outcome)
            pickle.loads(payload)  # an exception whose class takes other arguments than it keeps fails here
        except Exception:  # noqa: BLE001 - an exception that does not pickle is sent as its text
            payload = pickle.dumps(("error", RuntimeError(f"{type(outcome[1]).__name__}: {outcome[1]}")))
        with os.fdopen(write, "wb") as pipe:
            pipe.write(payload)
    finally:
        os._exit(code)  # no atexit handler, no flush of the parent's buffers, no return into the parent's code


def _collect(pid: int, fd: int, jobs: list[Callable[[], Any]]) -> tuple[str, Any]:
    """The child's outcome, read whole, once it ended; a child silent for `PATIENCE` s (a fork that deadlocked) is
    killed and its `jobs` run here instead, with a warning."""
    payload = b""
    with os.fdopen(fd, "rb", buffering=0) as pipe:
        while select.select([pipe], [], [], PATIENCE)[0]:
            chunk = pipe.read(1 << 16)
            if not chunk:
                break
            payload += chunk
        else:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            warnings.warn(f"a forked process gave no result in {PATIENCE:g} s and was stopped; its jobs ran here instead",
                          RuntimeWarning, stacklevel=3)
            try:
                return "ok", [job() for job in jobs]
            except BaseException as failed:  # noqa: BLE001 - raised by the caller, once every child is reaped
                return "error", failed
    _, status = os.waitpid(pid, 0)
    if not payload:
        return "error", RuntimeError(f"a forked process drawing figures ended without a result ({_ended(status)})")
    return pickle.loads(payload)


def _ended(status: int) -> str:
    """How a process ended, from its wait status."""
    if os.WIFSIGNALED(status):
        return f"killed by signal {os.WTERMSIG(status)}"
    return f"exit status {os.waitstatus_to_exitcode(status)}"
