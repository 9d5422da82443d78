"""The JAX-traceable chain model (robotadapt.robots.kinematic_tree) in a Slotine–Li closed loop, against the numpy loop
through Pinocchio (robotadapt.robots.pinocchio.PinocchioArm) on the same arm, measured in the same run.
Run alone: `python benchmarks/bench_kinematic_tree.py` (one to two minutes).

Arms: the Panda (example-robot-data URDF, fingers locked) and the PUMA 560 (its DH table, `symbolic.puma560`).
The loop: r = ė + Λe, τ = Y(q, q̇, q̇_d + Λe, q̈_d + Λė) φ̂ + K_v r, dφ̂/dt = Γ Yᵀ r (Λ = 5, K_v = 100 M(q₀),
Γ = 0.05 1, φ̂(0) = φ/2), plant q̈ = M⁻¹(τ − V_m q̇ − G) with the true φ, state z = [q, q̇, φ̂], fixed-step RK4 at
dt = 1 ms, reference q_d = q₀ + 0.2 sin(πt + k) per joint.

Measured:
- compile: time to the first result of `jit(regressor)` and of the `jit`-ed RK4 step, each in a fresh subprocess, with an
  empty JAX persistent compilation cache (cold), then again in another fresh subprocess with that cache filled (cached);
- step: one RK4 step per call from Python (dispatch included) and per step inside `lax.scan`; 1000 states per call,
  by `vmap` of the one-state step and through the model's own leading batch axis; the same RK4 step in numpy through
  `PinocchioArm` (C++ per call) and through this model's numpy path;
- the 10-s Panda loop: 10⁴ steps under one `lax.scan` (goal ≤ 0.5 s), after its compilation.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

DT = 1e-3
LAM, KV, GAMMA = 5.0, 100.0, 0.05  # K_v = KV · M(q₀, φ): SPD and scaled to the arm (a fixed K_v = 20 1 makes the
# Panda's light wrist, M's least eigenvalue 0.005 kg m², unstable under RK4 at 1 ms)


def arms(name: str) -> tuple[Any, Any]:
    """(KinematicTree, PinocchioArm) of the same arm."""
    from robotadapt.robots.kinematic_tree import KinematicTree
    from robotadapt.robots.pinocchio import PinocchioArm
    from robotadapt.robots.symbolic import puma560

    if name == "panda":
        return KinematicTree.example("panda"), PinocchioArm.example("panda")
    arm = puma560()
    return KinematicTree.from_symbolic(arm), PinocchioArm(arm.pinocchio_model(), name="puma560")


def loop(model: Any, phi: Any, xp: Any) -> tuple[Callable[[Any, Any], Any], Any]:
    """(RK4 step (t, z) → z, initial state) of the Slotine–Li loop on `model` with true parameters `phi`."""
    n = model.n
    phase = np.arange(n, dtype=float)
    q0 = np.full(n, 0.3)
    Kv = KV * np.asarray(model.mass_matrix(q0, np.asarray(phi)))

    def field(t: Any, z: Any) -> Any:
        q, dq, phi_hat = z[..., :n], z[..., n : 2 * n], z[..., 2 * n :]
        s, c = xp.sin(np.pi * t + phase), xp.cos(np.pi * t + phase)
        q_des, dq_des, ddq_des = q0 + 0.2 * s, 0.2 * np.pi * c, -0.2 * np.pi**2 * s
        e, de = q_des - q, dq_des - dq
        r = de + LAM * e
        Y = model.regressor(q, dq, dq_des + LAM * e, ddq_des + LAM * de)
        tau = (Y @ phi_hat[..., None])[..., 0] + r @ Kv.T
        ddq = model.forward_dynamics(q, dq, tau, phi)
        return xp.concat([dq, ddq, GAMMA * (Y * r[..., None]).sum(axis=-2)], axis=-1)

    def step(t: Any, z: Any) -> Any:
        k1 = field(t, z)
        k2 = field(t + DT / 2, z + DT / 2 * k1)
        k3 = field(t + DT / 2, z + DT / 2 * k2)
        k4 = field(t + DT, z + DT * k3)
        return z + DT / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    z0 = np.concatenate([q0 + 0.2 * np.sin(phase), 0.2 * np.pi * np.cos(phase), 0.5 * np.asarray(phi)])
    return step, z0


def per_call(fn: Callable[[], Any], calls: int, repeats: int = 5) -> float:
    """Median over repeats of the mean seconds per call."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls)
    return statistics.median(times)


# -- the child process: compile times with a given persistent cache ------------------------------------------------------

def child(name: str, cache: str) -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    model, _ = arms(name)
    step, z0 = loop(model, model.default_phi, jax.numpy)
    q, dq, v, a = np.random.default_rng(0).normal(size=(4, model.n))
    out = {}
    for key, fn, args in (("regressor", model.regressor, (q, dq, v, a)), ("step", step, (0.0, z0))):
        t0 = time.perf_counter()
        jax.block_until_ready(jax.jit(fn)(*args))
        out[key] = time.perf_counter() - t0
    print(json.dumps(out))


def compile_times(name: str) -> dict[str, tuple[float, float]]:
    """{what: (cold s, cached s)}, each from a fresh interpreter."""
    with tempfile.TemporaryDirectory() as cache:
        runs = []
        for _ in range(2):
            done = subprocess.run([sys.executable, __file__, "--child", name, cache], capture_output=True, text=True,
                                  check=True, env=os.environ | {"JAX_PLATFORMS": "cpu"})
            runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return {key: (runs[0][key], runs[1][key]) for key in runs[0]}


# -- the parent: step times -------------------------------------------------------------------------------------------

def step_times(name: str) -> dict[str, float]:
    """Seconds per RK4 step: jit single (per call), jit in lax.scan, vmap 1000 (per call), numpy Pinocchio, numpy
    KinematicTree; and the numpy Pinocchio step on the same state as a check of equal dynamics."""
    import jax

    jax.config.update("jax_enable_x64", True)
    jnp = jax.numpy
    model, pin_arm = arms(name)
    phi = model.default_phi
    step, z0 = loop(model, phi, jnp)
    jstep = jax.jit(step)
    z = jstep(0.0, z0)
    out = {"jit single": per_call(lambda: jstep(0.0, z).block_until_ready(), 300)}

    def scan(z: Any) -> Any:
        return jax.lax.scan(lambda c, t: (step(t, c), None), z, DT * jnp.arange(2000))[0]

    jscan = jax.jit(scan)
    jscan(z0).block_until_ready()
    out["jit in scan"] = per_call(lambda: jscan(z0).block_until_ready(), 1) / 2000
    batch = z0 + 0.01 * np.random.default_rng(1).normal(size=(1000, z0.size))
    jbatch = jax.jit(jax.vmap(step, in_axes=(None, 0)))
    jbatch(0.0, batch).block_until_ready()
    out["vmap 1000 per call"] = per_call(lambda: jbatch(0.0, batch).block_until_ready(), 20)
    jaxes = jax.jit(step)  # the model's own leading batch axis (its products switch to matmul on many states)
    jaxes(0.0, batch).block_until_ready()
    out["batch axis 1000 per call"] = per_call(lambda: jaxes(0.0, batch).block_until_ready(), 20)
    # numpy: Pinocchio (its own φ convention: joint frames for the URDF, Pinocchio's inertias for the DH arm)
    pstep, pz0 = loop(pin_arm, pin_arm.default_phi, np)
    out["numpy Pinocchio"] = per_call(lambda: pstep(0.0, pz0), 30)
    nstep, _ = loop(model, phi, np)
    out["numpy KinematicTree"] = per_call(lambda: nstep(0.0, z0), 30)
    out["numpy KinematicTree vmap-like 1000 per call"] = per_call(lambda: nstep(0.0, batch), 3)
    if name == "panda":  # same φ convention: the two numpy steps must agree
        out["|jit - numpy Pinocchio| after 1 step"] = float(np.abs(np.asarray(jstep(0.0, z0)) - pstep(0.0, z0)).max())
    return out


def long_loop() -> tuple[float, float, float]:
    """(compile s, run s, final |e|_max) of the 10-s Panda loop at 1 kHz under one lax.scan."""
    import jax

    jax.config.update("jax_enable_x64", True)
    jnp = jax.numpy
    model, _ = arms("panda")
    step, z0 = loop(model, model.default_phi, jnp)

    @jax.jit
    def run(z: Any) -> Any:
        return jax.lax.scan(lambda c, t: (step(t, c), None), z, DT * jnp.arange(10_000))[0]

    t0 = time.perf_counter()
    run(z0).block_until_ready()
    compile_and_run = time.perf_counter() - t0
    t0 = time.perf_counter()
    z = run(z0).block_until_ready()
    seconds = time.perf_counter() - t0
    n, t_end = model.n, 10.0
    q_des = 0.3 + 0.2 * np.sin(np.pi * t_end + np.arange(n))
    return compile_and_run - seconds, seconds, float(np.abs(np.asarray(z)[:n] - q_des).max())


def main() -> None:
    print("KinematicTree (JAX) vs PinocchioArm (numpy): Slotine–Li loop, RK4 at 1 ms")
    print(f"load average at start {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (times scale with it; ratios less)")
    for name in ("panda", "puma560"):
        c = compile_times(name)
        s = step_times(name)
        model, _ = arms(name)
        print(f"\n{name}: n = {model.n}, p = {model.p}")
        print(f"  compile jit(regressor)      cold {c['regressor'][0]:6.2f} s   cached {c['regressor'][1]:6.2f} s")
        print(f"  compile jit(RK4 step)       cold {c['step'][0]:6.2f} s   cached {c['step'][1]:6.2f} s")
        print(f"  step, jit, one call         {s['jit single'] * 1e6:9.1f} µs")
        print(f"  step, jit, inside lax.scan  {s['jit in scan'] * 1e6:9.1f} µs")
        print(f"  step, vmap 1000, one call   {s['vmap 1000 per call'] * 1e3:9.2f} ms  "
              f"({s['vmap 1000 per call'] * 1e6 / 1000:.2f} µs per state)")
        print(f"  step, batch axis 1000       {s['batch axis 1000 per call'] * 1e3:9.2f} ms  "
              f"({s['batch axis 1000 per call'] * 1e6 / 1000:.2f} µs per state)")
        print(f"  a state in a batch of 1000 costs 1/{s['jit in scan'] * 1000 / s['batch axis 1000 per call']:.1f} "
              "of a single run's step in lax.scan (goal: 1/5)")
        print(f"  step, numpy PinocchioArm    {s['numpy Pinocchio'] * 1e6:9.1f} µs   "
              f"(jit in scan is {s['numpy Pinocchio'] / s['jit in scan']:.0f}x faster, one jit call "
              f"{s['numpy Pinocchio'] / s['jit single']:.1f}x)")
        print(f"  step, numpy KinematicTree   {s['numpy KinematicTree'] * 1e6:9.1f} µs   "
              f"(1000 states in one call: {s['numpy KinematicTree vmap-like 1000 per call'] * 1e3:.1f} ms)")
        if "|jit - numpy Pinocchio| after 1 step" in s:
            print(f"  |jit step − numpy Pinocchio step| = {s['|jit - numpy Pinocchio| after 1 step']:.1e}")
    compile_s, seconds, err = long_loop()
    print(f"\nPanda, 10 s at 1 kHz (10⁴ RK4 steps) under one lax.scan: {seconds:.3f} s (goal ≤ 0.5 s; "
          f"compilation {compile_s:.2f} s; final |e| {err:.1e} rad)")
    print(f"load average at end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3])
    else:
        main()
