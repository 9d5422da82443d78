"""The closed loop as C (issue 28, docs/native.md): `simulation.backend = "c"` runs the driver's compiled program
translated to C — plant integration included — for continuous RK4 and sampled-data runs, single and batched, equal to
the numpy loop; where it does not apply it says so in one line."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import robotadapt as ra
from robotadapt.cli import main
from robotadapt.controllers import InertiaRelated
from robotadapt.native.build import compiler
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, simulate
from robotadapt.sim.batch import simulate_batch
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import Reference, constant, exponential_step, quintic, sum_of_sines

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler (set CC or install gcc)")


@pytest.mark.parametrize("name", ["example-6.3.1", "digital-6.3.1", "example-7.2.2", "example-6.2.2"])
def test_a_run_in_c_equals_the_numpy_loop(name):
    runs = {b: load(name, [f"simulation.backend='{b}'", "simulation.t_final=2.0"]).run() for b in ("c", "numpy")}
    c, ref = runs["c"], runs["numpy"]
    assert c.status == ref.status and c.t.shape == ref.t.shape
    assert np.max(np.abs(c.q - ref.q)) <= 1e-9 * max(1.0, np.max(np.abs(ref.q)))
    assert np.max(np.abs(c.x - ref.x)) <= 1e-9 * max(1.0, np.max(np.abs(ref.x)))
    assert c.info["backend"] == "c"


def test_a_batch_in_c_equals_the_numpy_batch():
    s = load("example-6.3.1", ["simulation.t_final=1.0"]).setup
    ctrls = [s.controller.__class__(s.controller.model, Lam=2.5, Kv=kv, Gamma=20.0, phi_hat0=[0.0, 0.0])
             for kv in (5.0, 10.0, 20.0)]
    out = {}
    for backend in ("c", "numpy"):
        integrator = type(s.integrator)(s.integrator.dt, backend=backend)
        out[backend] = simulate_batch(s.plant, ctrls, s.trajectory, t_final=1.0, integrator=integrator, q0=s.q0,
                                      dq0=s.dq0)
    assert out["c"].z.shape == out["numpy"].z.shape and out["c"].z.shape[1] == 3
    np.testing.assert_allclose(out["c"].z, out["numpy"].z, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("args, words", [
    (["--set", "simulation.method='RK45'", "--backend", "c"], "simulation.backend: the C backend runs fixed-step"),
    (["--set", "plant.engine='mujoco'", "--backend", "c"], "simulation.backend: a MuJoCo plant is stepped by MuJoCo"),
])
def test_where_c_does_not_apply_is_one_line(tmp_path, capsys, args, words):
    assert main(["run", "example-6.3.1", *args, "--no-plots", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and "\n" not in err


def test_without_a_compiler_backend_c_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CC", str(tmp_path / "nowhere"))
    assert main(["run", "example-6.3.1", "--backend", "c", "--no-plots", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("robotadapt: error: simulation.backend: no C compiler") and "\n" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["example-6.3.1", "problem-6.4-1", "problem-6.4-2"])
def test_a_second_run_reuses_the_first_runs_program(name):
    """A run leaves its law as it was (the inverses of Γ or K_I a Lyapunov or storage value needs are computed at
    construction, not at the first value): a second run of one scenario takes the first one's program, not a new
    compilation (a gcc build of seconds for an n-DOF arm)."""
    from robotadapt.tracing import PROGRAMS

    scenario = load(name, ["simulation.backend='c'", "simulation.t_final=0.2"])
    scenario.run()
    before = PROGRAMS.keys()
    scenario.run()
    assert PROGRAMS.keys() == before


def test_a_warm_process_runs_c_without_importing_jax():
    """A fresh process that finds its program in the store (by the transition's description, the package's source and
    JAX's version) runs it without tracing: JAX is not imported, and the run equals the one that traced it."""
    script = ("import sys; from robotadapt.studies.scenarios import load; "
              "r = load('example-6.3.1', [\"simulation.backend='c'\", 'simulation.t_final=1.5']).run(); "
              "print('jax' in sys.modules, repr(r.q[-1].tolist()))")
    runs = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split(" ", 1)
            for _ in range(2)]
    assert runs[1][0] == "False" and runs[1][1] == runs[0][1]


def test_a_users_class_is_part_of_the_stored_programs_key(tmp_path, monkeypatch):
    """A class from outside the package (a user's law) enters the stored key with its module's source, so an edited law
    is traced again; an object known only by its identity has no stable key (it is traced in each process)."""
    from robotadapt.sim.compiled import stable_key as _stable

    (tmp_path / "mylaw.py").write_text("class Law:\n    gain = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import mylaw

    key = ((mylaw.Law, (("gain", 1.0),)), 10, None)
    first = _stable(key)
    assert first is not None and "gain = 1.0" in first
    (tmp_path / "mylaw.py").write_text("class Law:\n    gain = 2.0\n")
    assert _stable(key) != first
    assert _stable(((mylaw.Law, (("f", ("id", 1234)),)), 10, None)) is None


TRAJECTORIES = {
    "sum of sines": lambda: sum_of_sines(2, [[0.5, 0.2], [0.3, 0.4]], [1.0, 2.5], phase=[[0.1, 0.0], [0.0, 0.7]],
                                         offset=[0.1, -0.2]),
    "exponential step": lambda: exponential_step(2, final=[1.0, -0.5], rate=[2.0, 3.0]),
    "quintic": lambda: quintic(2, [0.0, 0.2], [1.0, -0.8], t0=0.2, t1=0.9),
    "constant": lambda: constant(2, [0.3, -0.2]),
}


def _two_link_run(trajectory, backend, log_every):
    arm = TwoLinkArm()
    ctrl = InertiaRelated(arm, Lam=2.5, Kv=10.0, Gamma=20.0, phi_hat0=[0.0, 0.0])
    return simulate(Plant(arm, [0.8, 2.3]), ctrl, trajectory, t_final=1.0, integrator=RK4(1e-3, backend),
                    log_every=log_every)


def _state(result):
    return np.concatenate([result.q, result.dq, result.x], axis=1)


@pytest.mark.parametrize("kind", list(TRAJECTORIES))
@pytest.mark.parametrize("log_every", [1, 7])
def test_the_reference_evaluated_inside_the_c_program_equals_the_fed_one(kind, log_every):
    """A package trajectory is evaluated by the C program itself, at k·dt, (k + ½)·dt and (k + 1)·dt (RK4Step's
    `trajectory`); the numpy loop is fed the reference sampled in Python. The runs agree to round-off, logged rows
    included (log_every = 1: a program whose padded steps are skipped by a branch, not computed)."""
    c, ref = (_two_link_run(TRAJECTORIES[kind](), b, log_every) for b in ("c", "numpy"))
    assert c.info["backend"] == "c" and c.t.shape == ref.t.shape == (1000 // log_every + 1,)
    np.testing.assert_allclose(_state(c), _state(ref), rtol=0, atol=1e-12)
    assert np.ptp(c.q, axis=0).min() > 0.05  # the arm follows a reference that moves it


def test_a_users_trajectory_is_fed_and_its_kind_shares_a_program():
    """A trajectory from outside the package is sampled in Python and fed (the program cannot know it is traceable);
    two package trajectories of one kind and shape share one program (their arrays are its arguments)."""
    from robotadapt.tracing import PROGRAMS

    class Mine:
        n = 2

        def __call__(self, t):
            t = np.asarray(t, dtype=float)[..., None]
            return Reference(np.sin(t) + 0.0 * np.ones(2), np.cos(t) + 0.0 * np.ones(2), -np.sin(t) + 0.0 * np.ones(2))

    c, ref = (_two_link_run(Mine(), b, 1) for b in ("c", "numpy"))
    np.testing.assert_allclose(_state(c), _state(ref), rtol=0, atol=1e-12)
    _two_link_run(sum_of_sines(2, 0.5, 1.0), "c", 1)
    before = PROGRAMS.keys()
    other = _two_link_run(sum_of_sines(2, 0.9, 2.0), "c", 1)
    assert PROGRAMS.keys() == before
    np.testing.assert_allclose(other.q_des[-1], 0.9 * np.sin(2.0 * other.t[-1]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["example-6.3.1", "digital-6.3.1", "task-jacobian-2link"])
def test_the_records_of_a_c_run_are_computed_in_c_and_equal_numpys(name):
    """The logged torque, V, r, φ̂ and the reference of a C run come from a C program over the logged instants
    (sim.compiled.native_map, `RECORD_CHUNK` at a time), equal to numpy's recomputation to round-off."""
    from robotadapt.sim import compiled
    from robotadapt.tracing import PROGRAMS

    calls = []
    real = compiled.native_map
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(compiled, "native_map", lambda *a, **k: calls.append(1) or real(*a, **k))
        mp.setattr("robotadapt.sim.outputs.native_map", compiled.native_map)
        c = ra.load(name, ['simulation.backend="c"', "simulation.t_final=3.0"]).run()
    ref = ra.load(name, ['simulation.backend="numpy"', "simulation.t_final=3.0"]).run()
    assert calls and any(key[0] == "records" for key in PROGRAMS.keys())
    for field in ("tau", "V", "r", "phi_hat", "q_des", "e"):
        a, b = getattr(c, field), getattr(ref, field)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, float(np.abs(b).max())), err_msg=field)


def test_auto_runs_jax_while_a_long_c_program_builds_in_the_background(tmp_path, monkeypatch):
    """Under "auto", a C program over BACKGROUND_LINES lines (an n-DOF arm's: gcc takes 10–60 s) is built by a compiler
    process of its own: the run goes to JAX without a warning, and a run once the library is there to C, with the same
    numbers; backend "c" waits for its build."""
    import time
    import warnings

    from robotadapt.native import build
    from robotadapt.tracing import PROGRAMS

    monkeypatch.setenv("ROBOTADAPT_CACHE", str(tmp_path))
    monkeypatch.setattr(build, "BACKGROUND_LINES", 0)
    monkeypatch.setattr(PROGRAMS, "items", {})  # no program of an earlier test in this process
    scenario = load("example-6.3.1", ["simulation.t_final=2.5"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        first = scenario.run()
    assert first.info["backend"] == "jax"
    folder = build.cache_dir()
    for _ in range(240):  # the compiler process writes the library whole, then removes its marker
        if list(folder.glob("*.so")) and not list(folder.glob("*.building")):
            break
        time.sleep(0.25)
    second = scenario.run()
    assert second.info["backend"] == "c"
    np.testing.assert_allclose(second.q, first.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(second.x, first.x, rtol=0, atol=1e-12)
    monkeypatch.setattr(PROGRAMS, "items", {})
    other = load("example-6.3.1", ["simulation.t_final=0.7", "simulation.backend='c'", "simulation.log_every=7"]).run()
    assert other.info["backend"] == "c"  # a program of its own (log_every), built while the run waited
