"""JAX for the project's programs, at the lowest layer (the engine and the C translator both trace): the module itself
(:func:`jax_module`, with the persistent compilation cache and the package's pytrees registered) and the float64
scope (:func:`float64`).

float64 is on for the project's programs only (a thread-local scope around each entry point: the user's
`jax_enable_x64` stays as it was), so a run equals the numpy backend's to round-off. Compiled programs are cached on
disk (`$ROBOTADAPT_CACHE/jax`, default `~/.cache/robotadapt/jax`), so a second process does not pay the compilation
again; the cache directory is set only where the user has set none (JAX has one per process).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from functools import cache, wraps
from pathlib import Path
from typing import Any, TypeVar

from . import pytree
from .validation import ConfigError

F = TypeVar("F", bound=Callable[..., Any])
#: the primitives of a call to a nested program (a `jax.jit` inside the traced function): what every jaxpr walker of the
#: package (the C translator, the pass that writes short sums out) reads as "evaluate this jaxpr here"
CALLS = ("pjit", "jit", "closed_call", "core_call")


@cache
def jax_module() -> Any:
    """JAX, with the persistent compilation cache set up where the user has set none and the package's classes
    registered as pytrees; a ConfigError when it is not installed. float64 is not switched on here: :func:`float64`
    scopes it."""
    try:
        import jax
    except ImportError:
        raise ConfigError("simulation.backend", "the 'jax' backend needs JAX: pip install 'robotadapt[jax]'") from None
    if jax.config.jax_compilation_cache_dir is None:  # type: ignore[attr-defined]
        root = Path(os.environ.get("ROBOTADAPT_CACHE", Path.home() / ".cache" / "robotadapt"))
        jax.config.update("jax_compilation_cache_dir", str(root / "jax"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    pytree.register()
    return jax


class Programs:
    """The package's compiled programs in this process — the engine's XLA and C programs, the error-controlled solves,
    the one-off maps — by key, at most `bound` of them, the oldest dropped first: one cache, one bound."""

    def __init__(self, bound: int) -> None:
        self.bound = bound
        self.items: dict[Any, Any] = {}

    def get(self, key: Any, make: Callable[[], Any]) -> Any:
        """The program of `key`, made by `make()` the first time."""
        if key not in self.items:
            program = make()
            if len(self.items) >= self.bound:
                self.items.pop(next(iter(self.items)))
            self.items[key] = program
        return self.items[key]

    def __len__(self) -> int:
        return len(self.items)

    def keys(self) -> set[Any]:
        return set(self.items)


PROGRAMS = Programs(32)


def is_call(eqn: Any) -> bool:
    """Whether a jaxpr equation calls a nested program (its closed jaxpr in `eqn.params["jaxpr"]`)."""
    return eqn.primitive.name in CALLS and hasattr(eqn.params.get("jaxpr"), "jaxpr")


def float64(fn: F) -> F:
    """`fn` run with JAX's float64 on for the calling thread, within the call only (`jax.enable_x64`): the project's
    programs are traced and called in float64, and the user's `jax_enable_x64` is as it was afterwards."""
    @wraps(fn)
    def scoped(*args: Any, **kwargs: Any) -> Any:
        with jax_module().enable_x64(True):
            return fn(*args, **kwargs)

    return scoped  # type: ignore[return-value]
