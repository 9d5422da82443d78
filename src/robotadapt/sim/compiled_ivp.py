"""Error-controlled integration compiled: solve_ivp's explicit methods through diffrax (JAX), the same closed loop.

The vector field is :meth:`robotadapt.sim.loop.ClosedLoop.rate` with the reference evaluated inside the program (the
trajectories are array-API code), so the whole adaptive integration (steps, error estimates, step-size control, the
samples every `dt`) is one XLA program, cached by the loop's structure as a pytree as the fixed-step engine's are
(:mod:`robotadapt.pytree`): Example 6.3.1 over 10 s at rtol 1e-8 takes milliseconds instead of scipy's seconds.

The methods are the same Runge–Kutta pairs as scipy's: RK45 → `diffrax.Dopri5` (Dormand–Prince 5(4)), RK23 →
`diffrax.Bosh3` (Bogacki–Shampine 3(2)), DOP853 → `diffrax.Dopri8` (Dormand–Prince 8(7); scipy's DOP853 estimates its
error with a 5th- and 3rd-order pair), with a PI step-size controller on the same mixed tolerance atol + rtol·|z|. The
two integrators choose different steps, so their runs agree to the requested tolerance's global error (2e-7 on
Example 6.3.1 at rtol 1e-8, atol 1e-10: tests/test_compiled.py), not to round-off; `backend = "numpy"` keeps scipy.
Radau, BDF and LSODA have no counterpart in diffrax (its implicit solvers are ESDIRK methods) and stay on scipy.

A run stops where its state leaves `max_state` or stops being finite (an event at the end of the step; the samples
after it are dropped), or where the solver fails (its step shrinks to nothing: a non-finite derivative), with the
status a scipy run gives. A law with a guard (adaptive computed torque) or a delay line is refused: the guard's stop
time would be a rejected step's, not a sample's.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import pytree
from ..grid import Grid
from ..tracing import PROGRAMS, float64, jax_module
from ..validation import ConfigError
from .status import Status

if TYPE_CHECKING:
    from ..trajectories import Trajectory
    from .integrators import SolveIVP
    from .loop import ClosedLoop

Array = Any
METHODS = {"RK45": "Dopri5", "RK23": "Bosh3", "DOP853": "Dopri8"}  # scipy's name → diffrax's solver of the same pair
MAX_STEPS = 10**7  # accepted and rejected steps of one run at most: a failing run ends, never loops for ever


@cache
def _diffrax() -> Any:
    jax_module()  # float64 and the disk cache first
    try:
        import diffrax
    except ImportError:
        raise ConfigError("simulation.backend", "compiled solve_ivp methods need diffrax: pip install diffrax, or "
                          "use backend = 'numpy'") from None
    return diffrax


def check_compilable(loop: ClosedLoop, method: str) -> None:
    """A ConfigError naming why this loop's error-controlled run cannot be compiled (else nothing)."""
    if method not in METHODS:
        raise ConfigError("simulation.backend", f"{method} has no compiled counterpart (diffrax has no Radau IIA, BDF "
                          f"or LSODA); use method = 'RK45', 'RK23' or 'DOP853', or backend = 'numpy'")
    if loop.controller.has("guard") or loop.controller.has("delay_line"):
        raise ConfigError("simulation.backend", f"{type(loop.controller).__name__} (a guard or a delay line) runs "
                          "error-controlled on numpy only; use backend = 'numpy' or method = 'rk4'")


def _program(loop: ClosedLoop, traj: Trajectory, opts: SolveIVP) -> tuple[Callable[..., Any], list[Array]]:
    """The jitted diffrax solve for loops and references shaped like these, and their arrays to call it with."""
    leaves, structure = pytree.flatten((loop, traj))
    key = ("ivp", structure, opts.method, opts.rtol, opts.atol)
    return PROGRAMS.get(key, lambda: _solve(loop, structure, opts)), leaves


def _solve(loop: ClosedLoop, structure: Any, opts: SolveIVP) -> Callable[..., Any]:
    """The jitted diffrax solve of the loop and reference of `structure` (their leaves its first argument)."""
    dfx, jax = _diffrax(), jax_module()
    import optimistix  # diffrax's own dependency: the event's root finder

    jnp = jax.numpy

    def margin(t: Array, y: Array, args: Array, **kwargs: Any) -> Array:
        """max_state (`args`) − max|y|, y the state z: the run stops where it crosses zero (located by Newton's method
        on the step's interpolant, as scipy's event is by its root finder)."""
        y = loop.guarded_part(y)  # what the guard reads depends on the loop's structure only
        return jnp.where(jnp.all(jnp.isfinite(y)), args - jnp.max(jnp.abs(y)), -1.0)

    @jax.jit
    def run(arrays: list[Array], z0: Array, ts: Array, max_state: Array) -> tuple[Array, Array, Array, Array]:
        traced, reference = pytree.unflatten(structure, arrays)

        def field(t: Array, z: Array, args: Any) -> Array:
            return traced.rate(t, z, reference(t))[0]

        sol = dfx.diffeqsolve(dfx.ODETerm(field), getattr(dfx, METHODS[opts.method])(), ts[0], ts[-1], None, z0,
                              args=max_state, saveat=dfx.SaveAt(ts=ts, t1=True),
                              stepsize_controller=dfx.PIDController(opts.rtol, opts.atol),
                              event=dfx.Event(margin, root_finder=optimistix.Newton(1e-12, 1e-12)),
                              max_steps=MAX_STEPS, throw=False)
        # samples after a stop are inf; the one saved at t1 (the end, or the event's time) follows the last valid one
        t_end = jnp.max(jnp.where(jnp.isfinite(sol.ts), sol.ts, -jnp.inf))
        return sol.ys[:-1], t_end, jnp.any(jnp.asarray(sol.event_mask)), sol.result._value

    return run


@float64
def integrate_ivp(loop: ClosedLoop, traj: Trajectory, z0: Array, opts: SolveIVP, t_final: float,
                  max_state: float) -> tuple[Array, Array, Status]:
    """The logged times (every `opts.dt` on the run grid, :mod:`robotadapt.grid`), states and status of an
    error-controlled run, compiled."""
    check_compilable(loop, opts.method)
    run, arrays = _program(loop, traj, opts)
    t_eval = Grid(opts.dt, t_final).times()
    try:
        ys, t_end, stopped, code = run(arrays, np.asarray(z0, dtype=float), t_eval, max_state)
    except Exception as exc:  # tracing met code that needs concrete values
        name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
        raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                          f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None
    z = np.asarray(ys)
    guarded = loop.guarded_part(z)
    done = (t_eval <= float(t_end)) & np.all(np.isfinite(z), axis=1) & (np.max(np.abs(guarded), axis=1) <= max_state)
    keep = int(np.cumprod(done).sum())
    t, z = t_eval[:keep], z[:keep]
    if bool(stopped):
        return t, z, Status.at(float(t_end), f"state exceeded {max_state:g} in magnitude")
    if int(code) != 0:
        return t, z, Status.at(t[-1] if len(t) else 0.0, f"{opts.method} (diffrax {METHODS[opts.method]}) failed: "
                                 f"{_diffrax().RESULTS[int(code)]}")
    return t, z, Status.ok()
