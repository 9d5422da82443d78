"""The cores this process may run on: what a command spreads its work over by default (a sweep's workers, a fair
comparison's tunings, `robotadapt run`'s figures)."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system tells it, else the machine's count)."""
    affinity = getattr(os, "sched_getaffinity", None)
    return len(affinity(0)) if affinity is not None else os.cpu_count() or 1
