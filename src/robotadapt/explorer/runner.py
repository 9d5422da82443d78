"""Latest wins: a page's runs go to a worker thread one at a time; a change made while a run is going replaces any change
still waiting (none is queued behind another), and the result of a run that a newer change superseded is dropped."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Outcome:
    """What a job gave (`value`) or raised (`error`), its ticket and how long it took (s)."""

    ticket: int
    value: Any = None
    error: BaseException | None = None
    seconds: float = 0.0


class Runner:
    """Runs a page's jobs on `executor` (shared by the pages: one simulation at a time on the machine), newest first:
    `done(outcome)` is called, on the worker thread, for the newest job only."""

    def __init__(self, executor: Executor, done: Callable[[Outcome], None]) -> None:
        self.executor, self.done = executor, done
        self.lock = threading.Lock()
        self.latest = 0
        self.pending: tuple[int, Callable[[], Any]] | None = None
        self.started: float | None = None  # when the job under way started (None: idle)

    def submit(self, job: Callable[[], Any]) -> int:
        """Run `job` as soon as the job under way (if any) ends, in place of any job still waiting; its ticket."""
        with self.lock:
            self.latest += 1
            self.pending = (self.latest, job)
            if self.started is None:
                self._start()
            return self.latest

    def _start(self) -> None:
        assert self.pending is not None
        ticket, job = self.pending
        self.pending, self.started = None, time.perf_counter()
        self.executor.submit(self._run, ticket, job)

    def _run(self, ticket: int, job: Callable[[], Any]) -> None:
        started = time.perf_counter()
        try:
            outcome = Outcome(ticket, value=job(), seconds=time.perf_counter() - started)
        except Exception as exc:  # reported to the page, as the job's outcome
            outcome = Outcome(ticket, error=exc, seconds=time.perf_counter() - started)
        with self.lock:
            self.started = None
            current = ticket == self.latest
            if self.pending is not None:
                self._start()
        if current:
            self.done(outcome)
