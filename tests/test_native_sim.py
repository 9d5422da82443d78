"""The closed loop as C (issue 28, docs/native.md): `simulation.backend = "c"` runs the driver's compiled program
translated to C — plant integration included — for continuous RK4 and sampled-data runs, single and batched, equal to
the numpy loop; where it does not apply it says so in one line."""

from __future__ import annotations

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.native.build import compiler
from robotadapt.sim.batch import simulate_batch
from robotadapt.studies.scenarios import load

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
