"""The feature matrix (issue 23): every law × effect (continuous, sampled, actuator, sensor, MuJoCo) × engine (numpy,
jax, c, a batch on numpy, on jax and in C, the gradient of a tuning objective). Each cell either runs and agrees with
the numpy single run of its law and effect, or is a named refusal: the field and reason of the ConfigError
(NotBatchable included) the project raises. Anything else raised, or a disagreement, fails the test.

Agreement: same status and logged instants, q and τ within 1e-9 relative (of max(1, max |·|) of the reference), as the
project's other equality tests. The batch cell runs two loops that differ in q0 (the scenario's, and 0.05 rad more on
every joint) and compares each with its own numpy single run. The gradient cell builds the tuning problem on
`controller.Kv` (`Problem.evaluate` at the scenario's gains): its objective (rms_error) must equal the numpy run's
metric to 1e-9 relative and its gradient must be finite; it runs on the continuous, sampled and MuJoCo effects (the
actuator's and sensor's gradients are the sampled program with one more stage, left out for time). The MuJoCo numpy
cell is MuJoCo against the project's plant at the same control period (the two engines integrate the same equations
by the same method, docs/realtime.md); under a time-varying disturbance, which MuJoCo holds over each of its steps, it
is the named difference HELD, checked: equal to 1e-9 without the disturbance, to LOOSE with it.

The table, with each refusal's and difference's reason listed under it, is printed and must be what
docs/feature-matrix.md holds; `WRITE_FEATURE_MATRIX=1 pytest tests/test_feature_matrix.py -m slow` writes that file.
The two-law subset (FAST) runs in the fast suite and is checked against the doc's rows.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import robotadapt as ra
from robotadapt.analysis.metrics import metrics
from robotadapt.studies.gain_space import locate, parse_objective
from robotadapt.studies.tune import Problem
from robotadapt.validation import ConfigError

DOC = Path(__file__).resolve().parents[1] / "docs" / "feature-matrix.md"
TOL = 1e-9
LOOSE = 1e-3  # MuJoCo against the project's plant under a disturbance MuJoCo holds over its steps (1 ms)
T_FINAL = 0.3  # s: every law's run (the repetitive law: one period and a tenth, its own)
TS = 0.005  # s: the control period of the sampled effects
DQ0 = 0.05  # rad: the second run of a batch starts this much further on every joint

# the repetitive law's period: q_d = sin 6t, so that one period and a tenth is short; sampled at T/500 = 2.1 ms (its
# gains of 50 go unstable sampled slower: at 3 ms on sin t, τ reaches 3e4, 6 ms diverges)
_T = 2 * math.pi / 6
# row label → (packaged scenario, overrides that make it short: its law as packaged)
LAWS: dict[str, tuple[str, tuple[str, ...]]] = {
    "slotine_li": ("example-6.3.1", ()),
    "pd": ("example-6.2.1", ("controller={kind = 'pd', Kp = 25.0, Kv = 10.0}",)),
    "pd_gravity": ("example-6.2.1", ("controller={kind = 'pd_gravity', Kp = 25.0, Kv = 10.0, phi_hat0 = [0.85, 2.2]}",)),
    "computed_torque": ("example-6.2.1", ()),
    "adaptive_computed_torque": ("example-6.2.2", ("controller.phi_min=0.1", "controller.phi_max=10.0")),
    "passivity (gradient)": ("problem-6.4-1", ()),
    "passivity (Landau PI)": ("problem-6.4-2", ()),
    "passivity (σ-modification)": ("sigma-modification", ()),
    "composite": ("example-6.6.3", ()),
    "sign_robust": ("example-6.7.2", ()),
    "dcal": ("example-7.2.1", ()),
    "repetitive": ("example-7.2.2", ("trajectory.omega=6.0", f"controller.period={_T!r}", f"simulation.dt={_T / 1000!r}",
                                     f"simulation.t_final={1.1 * _T!r}", "simulation.log_every=1")),
    "task_slotine_li": ("task-circle-2link", ()),
    "adaptive_jacobian": ("task-jacobian-2link", ()),
    "operational_space": ("task-circle-2link", ("controller={kind = 'operational_space', Kp = 100.0, Kv = 20.0, "
                                                "phi_hat0 = [0.8, 2.3], posture = [0.0, 1.5]}",)),
}
FAST = ("slotine_li", "pd")  # the rows the fast suite computes
# the gain the gradient cell differentiates in, default controller.Kv: the sign-robust law's K_v is its base law's
GAIN = {"sign_robust": "controller.base.Kv"}


def _sampled(law: str) -> tuple[str, ...]:
    return (f"simulation.control_period={_T / 500!r}",) if law == "repetitive" else (f"simulation.control_period={TS}",)


# effect → its overrides (given the law)
EFFECTS = {
    "continuous": lambda law: (),
    "sampled": _sampled,
    "actuator": lambda law: (*_sampled(law), "plant.torque_limit=1e4"),
    "sensor": lambda law: (*_sampled(law), "plant.noise_q=1e-4"),
    "MuJoCo": lambda law: (*_sampled(law), "plant.engine='mujoco'"),
}
COLUMNS = ("numpy", "jax", "c", "batch numpy", "batch jax", "batch c", "gradient")
NOT_RUN = "·"
GRADIENT_EFFECTS = ("continuous", "sampled", "MuJoCo")  # the actuator's and sensor's gradients: the sampled code, not run


def _short(law: str) -> tuple[str, ...]:
    _, extra = LAWS[law]
    return extra if law == "repetitive" else (f"simulation.t_final={T_FINAL}", *extra)


def _load(law: str, effect: str, *more: str) -> Any:
    scenario, _ = LAWS[law]
    return ra.load(scenario, [*_short(law), *EFFECTS[effect](law), *more])


def _refusal(exc: ConfigError) -> str:
    return f"refused: {exc.field}: {exc.reason}"


def _check_same(run: Any, ref: Any, what: str) -> None:
    """`run` is `ref`: status, instants, q and τ to TOL relative."""
    assert run.status == ref.status, what
    assert run.t.shape == ref.t.shape, what
    np.testing.assert_allclose(run.t, ref.t, rtol=0, atol=1e-12, err_msg=what)
    for name in ("q", "tau"):
        a, b = getattr(run, name), getattr(ref, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=TOL * max(1.0, float(np.abs(b).max())), err_msg=f"{what}: {name}")


def _mujoco_available() -> bool:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def _q0(setup: Any) -> list[float]:
    return (np.asarray(setup.q0) + DQ0).tolist()


HELD = ("differs: MuJoCo holds the disturbance torque over each of its steps (plant/mujoco.py), the project's plant "
        "integrates it continuously: the loops agree to 1e-9 without the disturbance, to 1e-3 with it")


def _mujoco_cross_check(law: str, run: Any, disturbed: bool) -> str:
    """The MuJoCo run against the project's plant at the same control period: "ok" at TOL; with a time-varying
    disturbance (which MuJoCo holds over its steps) HELD, once the loops are shown equal without it."""
    own = _load(law, "sampled", "simulation.backend='numpy'").run()
    if not disturbed:
        _check_same(run, own, f"{law}, MuJoCo against the project's plant")
        return "ok"
    calm = ("plant.disturbance.amplitude=0.0",)
    _check_same(_load(law, "MuJoCo", *calm).run(), _load(law, "sampled", *calm).run(), f"{law}, MuJoCo, no T_d")
    for name in ("q", "tau"):
        a, b = getattr(run, name), getattr(own, name)
        assert np.abs(a - b).max() <= LOOSE * max(1.0, float(np.abs(b).max())), f"{law}, MuJoCo with T_d: {name}"
    return HELD


def _cells(law: str, effect: str) -> dict[str, str]:
    """The five cells of one law under one effect, each against the numpy single run of that law and effect."""
    out: dict[str, str] = {}
    try:
        scenario = _load(law, effect, "simulation.backend='numpy'")
        ref = scenario.run()
    except ConfigError as exc:  # the effect itself is refused: so is every cell of it
        return dict.fromkeys(COLUMNS, _refusal(exc))
    assert ref.ok, f"{law}, {effect}: the numpy single run stopped: {ref.status}"

    def cell(column: str, check: Any) -> None:
        try:
            out[column] = check() or "ok"
        except ConfigError as exc:
            out[column] = _refusal(exc)

    if effect == "MuJoCo":
        cell("numpy", lambda: _mujoco_cross_check(law, ref, scenario.setup.plant.disturbance is not None))
    else:
        out["numpy"] = "ok"  # the reference itself

    def single(backend: str) -> None:
        _check_same(_load(law, effect, f"simulation.backend='{backend}'").run(), ref, f"{law}, {effect}, {backend}")

    for backend in ("jax", "c"):
        cell(backend, lambda backend=backend: single(backend))

    def batch(backend: str) -> None:
        s = _load(law, effect, f"simulation.backend='{backend}'").setup
        refs = (ref, _load(law, effect, "simulation.backend='numpy'", f"plant.q0={_q0(s)}").run())
        res = ra.simulate_batch(s.plant, s.controller, s.trajectory, t_final=s.t_final, integrator=s.integrator,
                                q0=np.stack([s.q0, _q0(s)]), dq0=s.dq0, log_every=s.log_every, max_state=s.max_state)
        for i, single in enumerate(refs):
            _check_same(res.run(i), single, f"{law}, {effect}, batch {backend}, run {i}")

    for backend in ("numpy", "jax", "c"):
        cell(f"batch {backend}", lambda backend=backend: batch(backend))

    def gradient() -> None:
        gain = locate(scenario, GAIN.get(law, "controller.Kv"))
        objective = parse_objective("rms_error")
        problem = Problem(scenario, [gain], objective, None)
        _, grad, value, _, _, finite = problem.evaluate(problem.theta0)
        assert finite and np.all(np.isfinite(grad)), f"{law}, {effect}: gradient {grad}"
        if problem.switching:  # the gradient is its surrogate's; the exact law's objective is the forward program's
            value = float(problem.objectives(problem.theta0[None])[0][0])
        forward = objective.of_metrics(metrics(ref))
        assert abs(value - forward) <= TOL * max(1.0, abs(forward)), f"{law}, {effect}: J = {value} ≠ {forward}"

    if effect in GRADIENT_EFFECTS:
        cell("gradient", gradient)
    else:
        out["gradient"] = NOT_RUN
    return out


def compute(laws: tuple[str, ...]) -> dict[str, dict[tuple[str, str], str]]:
    """law → (effect, column) → "ok", "refused: field: reason", "differs: reason" or NOT_RUN (the MuJoCo cells when
    mujoco is not installed)."""
    matrix = {}
    for law in laws:
        row = {}
        for effect in EFFECTS:
            if effect == "MuJoCo" and not _mujoco_available():
                row |= {(effect, c): NOT_RUN for c in COLUMNS}
                continue
            row |= {(effect, c): v for c, v in _cells(law, effect).items()}
        matrix[law] = row
    return matrix


def _documented(row: dict[tuple[str, str], str]) -> dict[tuple[str, str], str]:
    """The cells a doc comparison checks: all of them, the MuJoCo ones only where mujoco is installed, the C ones only
    where a C compiler is."""
    from robotadapt.native.build import compiler

    return {k: v for k, v in row.items() if (k[0] != "MuJoCo" or _mujoco_available())
            and (not k[1].endswith("c") or compiler() is not None)}


def render(matrix: dict[str, dict[tuple[str, str], str]]) -> str:
    """The markdown table: refusals R1, R2, … and named differences D… listed under it, numbered in order of first
    appearance."""
    reasons: list[str] = []

    def mark(value: str) -> str:
        if value in ("ok", NOT_RUN):
            return value
        if value not in reasons:
            reasons.append(value)
        return f"{value[0].upper()}{reasons.index(value) + 1}"

    head = ["law", "scenario", *(f"{effect}: {c}" for effect in EFFECTS for c in COLUMNS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for law, row in matrix.items():
        cells = [law, LAWS[law][0], *(mark(row[effect, c]) for effect in EFFECTS for c in COLUMNS)]
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", f"ok: runs and agrees with the numpy single run; {NOT_RUN}: not run by the matrix; R: refused, D: "
              "differs by design, each with the project's reason:", ""]
    lines += [f"- **{reason[0].upper()}{i}** {reason}" for i, reason in enumerate(reasons, 1)]
    return "\n".join(lines) + "\n"


def parse(text: str) -> dict[str, dict[tuple[str, str], str]]:
    """The doc's table back into cells (the marks R… and D… replaced by their reasons)."""
    reasons = dict(re.findall(r"^- \*\*([RD]\d+)\*\* (.*)$", text, flags=re.M))
    rows = [line for line in text.splitlines() if line.startswith("| ")][1:]
    keys = [(effect, c) for effect in EFFECTS for c in COLUMNS]
    out = {}
    for line in rows:
        law, _, *cells = [c.strip() for c in line.strip("|").split("|")]
        out[law] = {k: reasons.get(v, v) for k, v in zip(keys, cells, strict=True)}
    return out


INTRO = """# Feature matrix

Every law of the project, one packaged scenario per law kind shortened to {t} s (the repetitive law on q_d = sin 6t,
one period and a tenth), under every effect: continuous time as packaged, sampled at {ts} s
(`simulation.control_period`; the repetitive law at T/500 = 2.1 ms), an actuator torque limit and sensor noise (both
sampled), and MuJoCo as the plant (`plant.engine = 'mujoco'`, sampled); on each engine: numpy, jax, c (the compiled
loop translated to C, docs/native.md), a batch of two initial states (`simulate_batch`) on numpy, on jax and in C, and
the gradient of the tuning objective rms_error
(`robotadapt tune`'s `Problem`) in `controller.Kv` (in the base law's K_v for sign_robust). A cell is **ok** when it
runs and agrees with the numpy single run of the same law and effect: q and τ to 1e-9 relative; the batch, each run
with its own single run; the gradient, its objective with the numpy run's and a finite gradient (for a switching law,
its smooth surrogate's gradient, the exact law's objective); MuJoCo against the project's plant at the same control period.
Otherwise it is a refusal **R*n*** with the field and the reason the project gives, or a difference by design
**D*n*** (both listed under the table). The gradient of the actuator and sensor effects is not run (·). Generated by
`tests/test_feature_matrix.py`, which fails when the project and this table disagree
(`WRITE_FEATURE_MATRIX=1 .venv/bin/pytest tests/test_feature_matrix.py -m slow` rewrites it).

"""


def document(table: str) -> str:
    return INTRO.format(t=T_FINAL, ts=TS) + table


@pytest.fixture(scope="module")
def fast_rows() -> dict[str, dict[tuple[str, str], str]]:
    return compute(FAST)


@pytest.fixture(scope="module")
def full_matrix(fast_rows: dict[str, dict[tuple[str, str], str]]) -> dict[str, dict[tuple[str, str], str]]:
    rest = compute(tuple(law for law in LAWS if law not in FAST))
    return {law: (fast_rows | rest)[law] for law in LAWS}


def test_the_fast_rows_of_the_feature_matrix_are_the_docs(fast_rows):
    """Slotine–Li and PD in every cell: each runs and agrees, or is the refusal docs/feature-matrix.md names."""
    print("\n" + render(fast_rows))
    documented = parse(DOC.read_text(encoding="utf-8"))
    for law, row in fast_rows.items():
        assert _documented(row) == _documented(documented[law]), law


@pytest.mark.slow
def test_the_feature_matrix_is_the_docs(full_matrix):
    """Every law: each cell runs and agrees with the numpy single run, or is a named refusal; the table is the doc's."""
    table = render(full_matrix)
    print("\n" + table)
    if os.environ.get("WRITE_FEATURE_MATRIX"):
        DOC.write_text(document(table), encoding="utf-8")
    text = DOC.read_text(encoding="utf-8")
    if not _mujoco_available():  # the MuJoCo cells are not run here: check the others
        documented = parse(text)
        assert {law: _documented(row) for law, row in full_matrix.items()} == \
            {law: _documented(row) for law, row in documented.items()}
        pytest.skip("mujoco is not installed: the MuJoCo cells are the doc's, unchecked")
    assert text == document(table)
