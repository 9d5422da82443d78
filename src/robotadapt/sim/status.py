"""How a run ended, as a record: :class:`Status` holds the code, the time, the reason, and renders as the text users
read ("ok", "diverged at t=0.57 s: state exceeded 1e+06 in magnitude"); nothing parses the text back."""

from __future__ import annotations

from typing import Any


class Status(str):
    """A run's end, built once by the driver that stopped it: `code` ("ok" or "diverged"), `t` (when it stopped; for a
    stop inside a step or an interval, its start), `t_end` (the end of that step or interval, else None) and `reason`
    (why, in words). It is the text it renders (a `str`), so it is written to metrics.json and compared as one."""

    code: str
    t: float | None
    t_end: float | None
    reason: str

    def __new__(cls, text: str, code: str = "ok", t: float | None = None, t_end: float | None = None,
                reason: str = "") -> Status:
        out = super().__new__(cls, text)
        out.code, out.t, out.t_end, out.reason = code, t, t_end, reason
        return out

    def __reduce__(self) -> tuple[Any, ...]:  # pickled with its fields (sweep chunks cross processes)
        return (Status, (str(self), self.code, self.t, self.t_end, self.reason))

    @classmethod
    def ok(cls) -> Status:
        return cls("ok")

    @classmethod
    def at(cls, t: float, reason: str) -> Status:
        """Stopped at `t` (the guard found the state at t bad)."""
        return cls(f"diverged at t={t:.6g} s: {reason}", "diverged", float(t), None, reason)

    @classmethod
    def within(cls, t: float, dt: float, reason: str) -> Status:
        """Stopped inside the step from `t` to `t + dt`, at one of its stages (a law or the plant refused the stage
        state; the state at t was fine)."""
        return cls(f"diverged within the step from {t:.6g} to {t + dt:.6g} s: {reason}", "diverged", float(t),
                   float(t + dt), reason)

    @classmethod
    def between(cls, t0: float, t1: float, reason: str) -> Status:
        """Stopped somewhere in [t0, t1], where the integrator cannot say when (solve_ivp keeps nothing of a stop)."""
        return cls(f"diverged between t={t0:.6g} and {t1:.6g} s: {reason}", "diverged", float(t0), float(t1), reason)

    @property
    def headline(self) -> str:
        """The text without the reason: "ok", "diverged at t=0.57 s" (a table's cell)."""
        return str(self) if self.code == "ok" else str(self)[: len(self) - len(self.reason) - 2]

    def record(self) -> dict[str, Any]:
        """The fields, for a JSON file."""
        return {"code": self.code, "t": self.t, "t_end": self.t_end, "reason": self.reason}
