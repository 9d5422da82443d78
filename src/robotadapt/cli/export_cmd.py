"""`robotadapt export SCENARIO --out DIR [--prefix NAME]`: the scenario's controller as C for a robot's real-time
loop (docs/native.md)."""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from functools import partial
from pathlib import Path
from typing import IO

from ..validation import ConfigError
from .common import add_scenario


def _write(text: str, f: IO[str]) -> None:
    f.write(text)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="the scenario's controller tick as C (NAME.c, NAME.h, an example harness): "
                       "NAME_reset and NAME_step for a robot's real-time loop, no Python")
    add_scenario(p)
    p.add_argument("--out", type=Path, help="folder for NAME.c, NAME.h, NAME_harness.c and export.json "
                   "(default: results/export-SCENARIO)")
    p.add_argument("--prefix", default="ra", metavar="NAME", help="the C prefix of the files and functions (default ra)")
    p.add_argument("--check", type=int, nargs="?", const=2000, metavar="TICKS",
                   help="build the example harness, feed it TICKS measurements (default 2000: the desired trajectory "
                   "with a few mrad of deviation) and compare its torques with the Python step, tick by tick; refused "
                   "beyond 1e-9 relative")


def main(args: argparse.Namespace) -> int:
    from ..files import atomic_write, writable_dir
    from ..native.build import require_compiler
    from ..native.controller import check_prefix
    from ..realtime import RealtimeController

    prefix = check_prefix(args.prefix)
    cc = require_compiler("export")
    ctrl = RealtimeController.from_scenario(args.scenario, list(args.set), backend="jax")
    name = Path(args.scenario).stem if args.scenario.endswith(".toml") else args.scenario
    clock = time.perf_counter()
    code = ctrl.export(prefix, f"the controller of scenario {name} at Ts = {ctrl.Ts:g} s")
    translated = time.perf_counter() - clock
    files = {f"{prefix}.h": code.header, f"{prefix}.c": code.source, f"{prefix}_harness.c": code.harness}
    build = [f"{cc} -O2 -c {prefix}.c", f"{cc} -O2 -o {prefix}_harness {prefix}_harness.c {prefix}.c -lm"]
    with tempfile.TemporaryDirectory() as tmp:  # the files must build before any is written
        for file, text in files.items():
            (Path(tmp) / file).write_text(text, encoding="utf-8")
        clock = time.perf_counter()
        for line in build:
            done = subprocess.run(line.split(), cwd=tmp, capture_output=True, text=True)
            if done.returncode != 0:
                first = (done.stderr.strip().splitlines() or ["(no message)"])[0]
                raise ConfigError("export", f"the exported C does not build ({line}): {first}")
        compiled = time.perf_counter() - clock
        checked = None if args.check is None else _check(args.scenario, list(args.set), Path(tmp) / f"{prefix}_harness",
                                                         args.check)
    out = writable_dir(args.out if args.out is not None else Path("results") / f"export-{name}")
    for file, text in files.items():
        atomic_write(out / file, partial(_write, text))
    record = {"scenario": name, "prefix": prefix, "joints": code.n, "state_size": code.state_size,
              "control_period": ctrl.Ts, "primitives": code.primitives, "files": list(files),
              "build": [line.replace(cc, "cc") for line in build], "translate_seconds": translated,
              "compile_seconds": compiled, **({} if checked is None else {"check": checked})}
    atomic_write(out / "export.json", lambda f: json.dump(record, f, indent=2))
    print(f"{name}: {code.n} joints, {code.state_size} doubles of state, {code.primitives} primitives translated "
          f"({translated:.1f} s), built with {cc} ({compiled:.1f} s); {prefix}_reset(state, q, dq) once, then "
          f"{prefix}_step(state, t, q, dq, tau) every {ctrl.Ts:g} s")
    if checked is not None:
        print(f"checked: the harness's torques equal the Python step over {checked['ticks']} ticks (largest difference "
              f"{checked['max_rel_difference']:.2g} of max |τ|)")
    print(f"wrote {out}/ (build: cc -O2 -c {prefix}.c; docs/native.md puts it in a libfranka or ros2_control loop)")
    return 0


CHECK_TOLERANCE = 1e-9  # relative to max |τ|: the C and the Python step differ by the order of their additions only


def _check(scenario: str, overrides: list[str], harness: Path, ticks: int) -> dict[str, float]:
    """The built harness against the Python step (`RealtimeController`, numpy) on `ticks` measurements: the desired
    trajectory (a task-space law's: the arm's start) with deterministic deviations of a few mrad, as a robot's log; a
    ConfigError beyond CHECK_TOLERANCE."""
    import numpy as np

    from ..realtime import RealtimeController

    if ticks < 1:
        raise ConfigError("--check", f"expected a positive number of ticks, got {ticks}")
    ctrl = RealtimeController.from_scenario(scenario, overrides, backend="numpy")
    n, t = ctrl.n, ctrl.Ts * np.arange(ticks)
    ref = ctrl.trajectory(t)
    wobble = 0.003 * np.sin(np.outer(t, 1.0 + np.arange(n)) + 0.4)
    q, dq = np.asarray(ref.q_des), np.asarray(ref.dq_des)
    if q.shape[-1] != n:  # a task-space law's reference is the hand's: the arm near its start instead
        from ..studies.scenarios import load

        start = load(scenario, overrides).setup
        q, dq = np.broadcast_to(start.q0, (ticks, n)), np.broadcast_to(start.dq0, (ticks, n))
    rows = np.column_stack([t, q + wobble, dq - 0.5 * wobble])
    text = "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in rows)
    done = subprocess.run([str(harness)], input=text, capture_output=True, text=True)
    if done.returncode != 0:
        raise ConfigError("--check", f"the harness failed ({(done.stderr.strip().splitlines() or ['no message'])[0]})")
    got = np.array([[float(v) for v in line.split()] for line in done.stdout.splitlines()])
    ctrl.reset(rows[0, 1 : 1 + n], rows[0, 1 + n :])
    want = np.array([ctrl.step(r[0], r[1 : 1 + n], r[1 + n :]) for r in rows])
    if got.shape != want.shape:
        raise ConfigError("--check", f"the harness printed {got.shape[0]} rows of {got.shape[-1]} for {ticks} ticks of "
                          f"{n} joints")
    scale = max(1.0, float(np.max(np.abs(want))))
    diff = np.abs(got - want).max(axis=1) / scale
    worst = int(np.argmax(diff))
    if not diff[worst] <= CHECK_TOLERANCE:
        raise ConfigError("--check", f"the harness's torque differs from the Python step by {diff[worst]:.3g} of max "
                          f"|τ| at tick {worst} (t = {t[worst]:g} s): report it with the scenario")
    return {"ticks": ticks, "max_rel_difference": float(diff[worst])}
