"""Whether a caller waits for a long C program to build (`simulation.backend = "auto"` need not: JAX runs meanwhile), a
module of its own so that a run on another backend does not import the translator."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any

from ..validation import ConfigError

_PATIENT: ContextVar[bool] = ContextVar("robotadapt_patient", default=True)


class Building(ConfigError):
    """The program's library (to be at `path`) is being built by a compiler process of its own
    (:func:`robotadapt.native.build.shared_library` where the caller need not wait); `later` loads the program once it
    is there (a :class:`robotadapt.native.build.Later`)."""

    def __init__(self, field: str, message: str, path: Path) -> None:
        super().__init__(field, message)
        self.path = path
        self.later: Any = None


@contextmanager
def patience(wait: bool) -> Iterator[None]:
    """Within the block, `wait=False`: a long program (over `build.BACKGROUND_LINES` lines) is built by a compiler
    process of its own and raises :class:`Building` instead of being waited for (`simulation.backend = "auto"` runs
    JAX meanwhile; a later run, or the next process, finds the library)."""
    token = _PATIENT.set(wait)
    try:
        yield
    finally:
        _PATIENT.reset(token)


def patient() -> bool:
    """Whether the caller waits for a long program's build (the default)."""
    return _PATIENT.get()
