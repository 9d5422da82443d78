"""Shared fixtures."""

from __future__ import annotations

from collections.abc import Iterator

import pytest


@pytest.fixture
def x64() -> Iterator[None]:
    """float64 JAX for a test that calls JAX itself (as a user's own code would ask for it): the project scopes
    float64 to its own programs and leaves the process's `jax_enable_x64` as it was."""
    from robotadapt.tracing import jax_module

    with jax_module().enable_x64(True):
        yield
