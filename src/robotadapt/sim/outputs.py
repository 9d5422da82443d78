"""What a run's record holds besides its states, recomputed after integration from the pure maps of the controller and
the plant, vectorized over the logged instants: torque, V(t), r(t), φ̂ as the torque uses it, and the controller's
monitor signals (V_φ(t), λ_min(P⁻¹(t)); the laws' proofs, docs/laws.md). The passivity integral (6.4.4) is not
recomputed here: it is integrated with the loop at every step (ClosedLoop.monitored), so no monitor depends on how
often the run was logged.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..arrays import array_namespace, matvec
from ..trajectories import Reference, Trajectory
from ..trajectories import traceable as is_traceable
from ..validation import ConfigError
from .compiled import compiled_map, native_map
from .loop import ClosedLoop
from .result import SimulationResult
from .status import Status

Array = Any
COMPILED_OUTPUTS = 10**6  # logged states × parameters from which the maps are evaluated by JAX (a sweep's chunk, an
# n-DOF arm's long run): numpy's per-call cost is then the larger, JAX's tracing the smaller


def outputs(loop: ClosedLoop, trajectory: Trajectory, t: Array, z: Array, status: Status, wall: float,
            info: dict[str, Any], logged: dict[str, Array] | None = None,
            folded: dict[str, Any] | None = None) -> SimulationResult:
    """Recompute torque, V(t), r(t) and the passivity integral (6.4.4) from the pure maps at the logged instants.

    `logged` (sampled-data mode) holds the torque applied at each logged tick (`tau`) and what the run recorded
    besides (`tau_commanded`, `q_measured`, `dq_measured`); in continuous time the applied torque is the saturated
    command. V, r and the passivity integral are evaluated on the true state, φ̂ from what the controller saw. The
    truth is the plant's φ(t) when the controller's model is the plant's; the result's `phi` is its value at the last
    sample, and `monitors["phi_true"]` its history when it changed during the run (a payload attached). `folded`: the
    metrics the run folded at every step (:mod:`robotadapt.sim.running`), kept as the result's `running`.
    """
    signals, extras = _signals(loop, trajectory, t, t, z, logged, native=info.get("backend") == "c")
    truth = signals.pop("truth")
    phi = None if truth is None else truth[-1] if truth.ndim == 2 else truth
    if phi is not None and loop.plant.varies:
        extras["phi_true"] = truth
    return _result(loop.controller, t, signals, phi, extras, status, wall, info, folded)


def batch_outputs(loop: ClosedLoop, controllers: tuple[Any, ...], trajectory: Trajectory, t: Array, z: Array,
                  status: tuple[Status, ...], wall: float, info: list[dict[str, Any]],
                  logged: dict[str, Array] | None = None,
                  folded: list[dict[str, Any] | None] | None = None) -> list[SimulationResult]:
    """:func:`outputs` of N runs logged together, `z` `(T, N, m)` (every run logged at every `t`), computed once
    for the batch by the merged `loop` (gains stacked over the runs) and `trajectory`: run i's record is its slice,
    with `controllers[i]` for the signals that need one run's controller. The plant's φ must not change during the
    runs (no payload attached after t = 0). `logged`: as for :func:`outputs`, `(T, N, n)`."""
    signals, extras = _signals(loop, trajectory, t, t[:, None], z, logged)
    truth = signals.pop("truth")
    out = []
    for i, ctrl in enumerate(controllers):
        phi = None if truth is None else truth[i] if truth.ndim == 2 else truth
        run = {k: None if v is None else v[:, i] for k, v in signals.items()}
        out.append(_result(ctrl, t, run, phi, {k: v[:, i] for k, v in extras.items()}, status[i], wall, info[i],
                           None if folded is None else folded[i]))
    return out


def _signals(loop: ClosedLoop, trajectory: Trajectory, t: Array, times: Array, z: Array,
             logged: dict[str, Array] | None, native: bool = False) -> tuple[dict[str, Array | None], dict[str, Array]]:
    """The record's arrays at the logged `t` (`times`: t shaped to broadcast against the runs' axes of `z`), the
    true φ there under "truth" (None when unknown, or when the law estimates none of the plant's parameters), and
    the extra monitor series. `native` (a run of the C backend): the reference and the maps evaluated by a C program
    too (:func:`~robotadapt.sim.compiled.native_map`), where the models and the trajectory are array-API code."""
    ctrl, plant = loop.controller, loop.plant
    q, dq, x = loop.split(z)
    extras = dict(logged or {})
    truth = plant.truth_for(ctrl.model, times)
    traceable = plant.model.traceable and ctrl.model.traceable
    if native and traceable and is_traceable(trajectory) and z.ndim == 2:
        try:
            return _native_signals(loop, trajectory, times, z, logged, extras, truth)
        except ConfigError:  # host-side code in the law: numpy
            pass
    shape = q.shape[:-1] + (ctrl.error_size,)  # the reference's: joints, or a task-space law's coordinates
    ref = Reference(*(a if a.shape == shape else np.broadcast_to(a, shape) for a in trajectory(times)))
    args = (times, z, ref, extras.get("q_measured"), extras.get("dq_measured"), truth)
    if traceable and z.size // z.shape[-1] * max(ctrl.model.p, plant.model.p) >= COMPILED_OUTPUTS:
        try:
            maps = compiled_map(_maps, loop, (logged is None,), *args)
        except ConfigError:  # a law with host-side code: numpy
            maps = _maps(loop, (logged is None,), *args)
    else:
        maps = _maps(loop, (logged is None,), *args)
    maps = {**maps, "q_des": ref.q_des, "dq_des": ref.dq_des, "ddq_des": ref.ddq_des}
    return _assemble(loop, z, maps, logged, extras, truth), extras


def _assemble(loop: ClosedLoop, z: Array, maps: dict[str, Array | None], logged: dict[str, Array] | None,
              extras: dict[str, Array], truth: Array | None) -> dict[str, Array | None]:
    """The record's arrays from the maps at the logged instants (and `extras`, completed here); a map that is None
    may be absent (a native program returns arrays only)."""
    plant = loop.plant
    q, dq, x = loop.split(z)
    if logged is None:
        tau = maps["tau"]
        if plant.actuator is not None:
            extras["tau_commanded"] = maps["commanded"]
    else:
        tau = extras.pop("tau")
    phi_hat = maps["phi_hat"]
    assert phi_hat is not None
    if truth is not None and phi_hat.shape[-1] != plant.model.p:
        truth = None  # the law estimates no parameters of the plant's: the record has no true φ
    passivity = None
    carried = loop.passivity(z)  # integrated with the loop (ClosedLoop.monitored), not from the logged samples
    if carried is not None:
        passivity, extras["passivity_running_min"] = carried
    extras.update(plant.extra_series(z[..., : loop.m]))
    if truth is not None and maps.get("V_phi") is not None:
        extras["parameter_lyapunov"] = maps["V_phi"]
    return {"q": q, "dq": dq, "x": x, "q_des": maps["q_des"], "dq_des": maps["dq_des"], "ddq_des": maps["ddq_des"],
            "tau": tau, "V": maps.get("V"), "r": maps.get("r"), "phi_hat": phi_hat, "passivity": passivity, "truth": truth,
            "errors": maps.get("errors")}


def _native_signals(loop: ClosedLoop, trajectory: Trajectory, times: Array, z: Array, logged: dict[str, Array] | None,
                    extras: dict[str, Array], truth: Array | None) -> tuple[dict[str, Array | None], dict[str, Array]]:
    """:func:`_signals` of one run with the reference and :func:`_maps` in C."""
    each = None if truth is None else np.broadcast_to(truth, (times.shape[0], np.shape(truth)[-1]))
    maps = native_map(_records, (loop, trajectory), (logged is None,),
                      (times, z, extras.get("q_measured"), extras.get("dq_measured"), each))
    return _assemble(loop, z, maps, logged, extras, truth), extras


def _records(pair: tuple[ClosedLoop, Trajectory], flags: tuple[bool], times: Array, z: Array,
             q_measured: Array | None, dq_measured: Array | None, truth: Array | None) -> dict[str, Array | None]:
    """The reference at the logged instants and :func:`_maps` there, one program."""
    loop, trajectory = pair
    ref = trajectory(times)
    out = _maps(loop, flags, times, z, ref, q_measured, dq_measured, truth)
    return {**out, "q_des": ref.q_des, "dq_des": ref.dq_des, "ddq_des": ref.ddq_des}


def _maps(loop: ClosedLoop, flags: tuple[bool], times: Array, z: Array, ref: Reference, q_measured: Array | None,
          dq_measured: Array | None, truth: Array | None) -> dict[str, Array | None]:
    """The pure maps of the controller and the plant at the logged states, array-API code (numpy, or JAX through
    :func:`~robotadapt.sim.compiled.compiled_map`): the commanded and applied torque (continuous time, `flags[0]`), φ̂
    as the torque uses it, V and r."""
    ctrl, plant = loop.controller, loop.plant
    q, dq, x = loop.split(z)
    out: dict[str, Array | None] = {"commanded": None, "tau": None, "V": None, "r": None, "V_phi": None}
    if flags[0]:
        out["commanded"] = loop.torque(times, z, ref)
        out["tau"] = plant.saturate(out["commanded"])
    q_seen = q if q_measured is None else q_measured
    dq_seen = dq if dq_measured is None else dq_measured
    out["phi_hat"] = ctrl.phi_hat_at(times, x, q_seen, dq_seen, ref)
    if truth is not None:
        out["V"] = ctrl.lyapunov(times, x, q, dq, ref, truth)
    out["r"] = ctrl.filtered_error(times, x, q, dq, ref)
    if loop.w and out["V"] is not None and out["r"] is not None:  # V_φ, for the passivity monitor (controller_series)
        out["V_phi"] = parameter_part(ctrl.model, q, out["r"], out["V"], truth)
    if ctrl.has("tracking_error"):  # a task-space law: e = x_d − x(q), not q_des − q
        out["errors"] = array_namespace(q).stack(ctrl.tracking_error(q, dq, ref), axis=-2)
    return out


def _result(ctrl: Any, t: Array, signals: dict[str, Array | None], phi: Array | None, extras: dict[str, Array],
            status: Status, wall: float, info: dict[str, Any], folded: dict[str, Any] | None = None) -> SimulationResult:
    phi_hat = signals["phi_hat"]
    assert phi_hat is not None
    caveat = ctrl.passivity_caveat()  # a law whose passivity claim its gains may not imply
    if signals["passivity"] is not None and caveat is not None:
        info = {**info, "passivity_caveat": caveat}
    if signals.get("V") is not None and ctrl.lyapunov_caveat() is not None:  # V holds no proof here (a held φ̂)
        info = {**info, "lyapunov_caveat": ctrl.lyapunov_caveat()}
    result = SimulationResult(t=t, **signals, phi=phi,  # type: ignore[arg-type]
                              param_names=ctrl.model.param_names if phi_hat.shape[-1] else (),
                              state_names=ctrl.state_names, status=status, wall_time=wall, info=info, running=folded)
    series = controller_series(result, ctrl, extras.get("phi_true"), extras.get("parameter_lyapunov"))
    return replace(result, monitors={**series, **extras})


def parameter_part(model: Any, q: Array, r: Array, V: Array, phi: Array) -> Array:
    """V_φ = V − ½ rᵀ M(q, φ) r, the parameter part of V (½ φ̃ᵀ Γ⁻¹ φ̃ in (6.3.7) and (6.4.8), ½ φ̃ᵀ P⁻¹ φ̃ in (6.6.29)),
    whose value at 0 bounds the passivity integral (6.4.4) (:func:`controller_series`)."""
    return V - 0.5 * (r * matvec(model.mass_matrix(q, phi), r)).sum(axis=-1)


def controller_series(res: SimulationResult, controller: Any, phi_t: Array | None = None,
                      V_phi: Array | None = None) -> dict[str, Array]:
    """Signals of the run that need its controller, at the logged instants:

    - `parameter_lyapunov`: V_φ(t) = V(t) − ½ rᵀ M(q) r, the parameter part of V (½ φ̃ᵀ Γ⁻¹ φ̃ in (6.3.7) and (6.4.8),
      ½ φ̃ᵀ P⁻¹ φ̃ in (6.6.29)), for controllers with a passivity output and a known truth. Its initial value is the
      passivity bound β of (6.4.4): d V_φ/dt = −rᵀ Z φ̃ − (non-negative terms), so ∫₀ᵗ −rᵀ Z φ̃ ≥ −V_φ(0).
    - `lambda_min_P_inv`: λ_min(P⁻¹(t)) of the least-squares gain (composite law, (6.6.27)); it grows without bound
      exactly when the infinite-integral condition (6.6.18) holds.

    `phi_t`: the true φ(t) at the logged instants when it changed during the run (a payload attached); M(q, φ(t)) is
    then taken at each instant, as V was, so that V_φ and β = V_φ(0) are those of the arm as it was then. The bound
    (6.4.4) is for a constant φ: where φ jumps, V_φ jumps with it (φ̂ does not), and ∫₀ᵗ −rᵀZφ̃ ≥ −V_φ(0) − Σ ΔV_φ.
    `parameter_lyapunov_jump` holds ΔV_φ = V_φ(φ after) − V_φ(φ before) at the first logged instant after each change
    (both with that instant's state), 0 elsewhere. `V_phi`: V_φ as the record's maps computed it (:func:`_maps`, in C
    for a run of the C backend), else computed here.
    """
    out: dict[str, Array] = {}
    if res.passivity is not None and res.V is not None and res.r is not None and res.phi is not None:
        out["parameter_lyapunov"] = V_phi if V_phi is not None else parameter_part(
            controller.model, res.q, res.r, res.V, res.phi if phi_t is None else phi_t)
        if phi_t is not None:
            before = np.concatenate([phi_t[:1], phi_t[:-1]])
            ref = Reference(res.q_des, res.dq_des, res.ddq_des)
            V_before = controller.lyapunov(res.t, res.x, res.q, res.dq, ref, before)
            changed = np.any(before != phi_t, axis=-1)
            out["parameter_lyapunov_jump"] = np.where(changed, out["parameter_lyapunov"] - parameter_part(
                controller.model, res.q, res.r, V_before, before), 0.0)
    out.update(controller.monitors(res.x, res.q))  # the law's own (least squares: λ_min(P⁻¹); the hand's σ_min(J))
    return out
