"""The controller exported as C (issue 28, docs/native.md): `robotadapt export` writes files that build, and its example
harness, compiled and fed a log, gives the torques of `RealtimeController`'s numpy path tick by tick (1e-12 relative)
on the two-link arm, the PUMA 560, the Panda, the repetitive law (its delay line) and the composite law;
`RealtimeController(backend="c")` equals the numpy path on every other law; without a compiler "auto" falls back to JAX
saying so once and "c" and `export` refuse in one line; a primitive the translator lacks is named."""

from __future__ import annotations

import json
import subprocess
import warnings

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.native import build
from robotadapt.realtime import RealtimeController

pytestmark = pytest.mark.skipif(build.compiler() is None, reason="no C compiler (set CC or install gcc)")


def measurements(ctrl: RealtimeController, ticks: int) -> np.ndarray:
    """Rows [t, q, q̇]: the desired trajectory with deterministic deviations of a few mrad, as a robot's log."""
    t = ctrl.Ts * np.arange(ticks)
    ref = ctrl.trajectory(t)
    wobble = 0.003 * np.sin(np.outer(t, 1.0 + np.arange(ctrl.n)) + 0.4)
    return np.column_stack([t, np.asarray(ref.q_des) + wobble, np.asarray(ref.dq_des) - 0.5 * wobble])


def reference(name: str, rows: np.ndarray) -> np.ndarray:
    """τ per row from the numpy path of RealtimeController, reset at the first row."""
    ctrl = RealtimeController.from_scenario(name, backend="numpy")
    n = ctrl.n
    ctrl.reset(rows[0, 1 : 1 + n], rows[0, 1 + n :])
    return np.array([ctrl.step(r[0], r[1 : 1 + n], r[1 + n :]) for r in rows])


def assert_ticks_equal(got: np.ndarray, want: np.ndarray) -> None:
    scale = max(1.0, float(np.max(np.abs(want))))
    assert got.shape == want.shape
    assert np.max(np.abs(got - want)) <= 1e-12 * scale, np.max(np.abs(got - want)) / scale


@pytest.mark.parametrize("name, ticks", [("example-6.3.1", 10_000), ("puma560-slotine-li", 1000),
                                         ("panda-slotine-li", 1000), ("example-7.2.2", 10_000),
                                         ("example-6.6.3", 2000), ("panda-composite", 300)])
def test_the_export_builds_and_its_harness_gives_the_numpy_torques(tmp_path, capsys, name, ticks):
    export_and_compare(tmp_path, capsys, name, ticks)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["puma560-slotine-li", "panda-slotine-li", "panda-composite"])
def test_ten_thousand_ticks_of_the_n_dof_exports(tmp_path, capsys, name):
    export_and_compare(tmp_path, capsys, name, 10_000)


def export_and_compare(tmp_path, capsys, name: str, ticks: int) -> None:
    """Export `name`, build its harness, feed it `ticks` measurements, compare with the numpy path tick by tick."""
    out = tmp_path / "c"
    assert main(["export", name, "--out", str(out), "--prefix", "ctl"]) == 0
    record = json.loads((out / "export.json").read_text())
    assert sorted(record["files"]) == ["ctl.c", "ctl.h", "ctl_harness.c"] and "wrote" in capsys.readouterr().out
    cc = build.compiler()
    subprocess.run([cc, "-O2", "-std=c99", "-Wall", "-Werror", "-c", "ctl.c"], cwd=out, check=True)  # as the header says
    subprocess.run([cc, "-O2", "-o", "harness", "ctl_harness.c", "ctl.c", "-lm"], cwd=out, check=True)
    ctrl = RealtimeController.from_scenario(name, backend="numpy")
    rows = measurements(ctrl, ticks)
    text = "\n".join(" ".join(repr(float(v)) for v in row) for row in rows)
    done = subprocess.run([str(out / "harness")], input=text, capture_output=True, text=True, check=True)
    got = np.array([[float(v) for v in line.split()] for line in done.stdout.splitlines()])
    assert record["joints"] == ctrl.n
    assert_ticks_equal(got, reference(name, rows))


@pytest.mark.parametrize("name", ["example-6.2.2", "example-6.5.1", "problem-6.4-1", "problem-6.4-2", "example-6.7.2",
                                  "sigma-modification", "ur5-dcal", "noise-6.3.1", "example-7.2.1", "payload-change",
                                  "digital-6.3.1", "problem-6.2-1", "panda-natural"])
def test_the_c_backend_equals_the_numpy_path_tick_by_tick(name):
    ctrl = RealtimeController.from_scenario(name, backend="c")
    rows = measurements(ctrl, 200 if name.startswith("panda") else 500)
    n = ctrl.n
    ctrl.reset(rows[0, 1 : 1 + n], rows[0, 1 + n :])
    got = np.array([ctrl.step(r[0], r[1 : 1 + n], r[1 + n :]) for r in rows])
    assert_ticks_equal(got, reference(name, rows))
    numpy = RealtimeController.from_scenario(name, backend="numpy")
    numpy.reset(rows[0, 1 : 1 + n], rows[0, 1 + n :])
    for r in rows:
        numpy.step(r[0], r[1 : 1 + n], r[1 + n :])
    np.testing.assert_allclose(ctrl.x, numpy.x, rtol=1e-10, atol=1e-12)  # the natural law's log-Cholesky state: 5e-12


def test_the_library_is_built_once_per_source(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOTADAPT_CACHE", str(tmp_path))
    source = "double twice(double x) { return 2 * x; }\n"
    first = build.shared_library(source)
    stamp = first.stat().st_mtime_ns
    assert build.shared_library(source) == first and first.stat().st_mtime_ns == stamp
    assert build.shared_library(source + "\n") != first
    assert [p.name for p in (tmp_path / "c").iterdir() if not p.name.endswith(".so")] == []  # no half-written file


def test_without_a_compiler_auto_falls_back_once_and_c_and_export_refuse(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    from robotadapt import realtime

    realtime._without_compiler.cache_clear()
    with pytest.warns(RuntimeWarning, match="no C compiler found.*apt-get install gcc") as caught:
        first = RealtimeController.from_scenario("example-6.3.1")
        second = RealtimeController.from_scenario("example-6.3.1")
    said = [w for w in caught if "no C compiler found" in str(w.message)]  # other libraries' warnings aside
    assert first.backend == second.backend == "jax" and len(said) == 1
    with pytest.raises(Exception, match="simulation.backend: no C compiler .*apt-get install gcc"):
        RealtimeController.from_scenario("example-6.3.1", backend="c")
    assert main(["export", "example-6.3.1", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("robotadapt: error: export: no C compiler") and "\n" not in err
    assert not (tmp_path / "out").exists()
    realtime._without_compiler.cache_clear()


def test_a_primitive_the_translator_lacks_is_named_in_one_line(tmp_path, capsys, monkeypatch):
    """With scatter taken out of the translator, the repetitive law's tick (its delay line writes by scatter) cannot
    be exported: one line names the primitive, nothing is written; "auto" runs it on JAX instead, saying so."""
    from robotadapt.native.c99 import Translator

    monkeypatch.delattr(Translator, "p_scatter")
    assert main(["export", "example-7.2.2", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("robotadapt: error: native: the C translator has no primitive 'scatter'") and "\n" not in err
    assert not (tmp_path / "out").exists()
    ctrl = RealtimeController.from_scenario("example-7.2.2")
    assert ctrl.backend == "c"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ctrl.reset(np.zeros(2), np.zeros(2))
    assert ctrl.backend == "jax" and any("no primitive 'scatter'" in str(w.message) for w in caught)
    assert np.all(np.isfinite(ctrl.step(0.0, np.zeros(2), np.zeros(2))))


def test_a_bad_prefix_is_refused(tmp_path, capsys):
    assert main(["export", "example-6.3.1", "--prefix", "2fast", "--out", str(tmp_path / "o")]) == 2
    assert "--prefix: expected a C identifier" in capsys.readouterr().err
