"""Sweeps (`robotadapt.studies.sweep`, `robotadapt sweep`): expansion of grid × random points and their seeds, rows equal to
single runs, resume after an interruption, local processes and a Dask cluster giving the same table, bad input.

Runs are Example 6.3.1 cut to 0.2 s so that a sweep takes well under a second.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from robotadapt.analysis.metrics import metrics
from robotadapt.cli import main
from robotadapt.sim import simulate
from robotadapt.studies import sweep as sweep_module
from robotadapt.studies.scenarios import load
from robotadapt.studies.sweep import (
    Point,
    log_every,
    make_sweep,
    parse_grid,
    parse_random,
    read_table,
    run_chunk,
    run_sweep,
    seed_of,
)
from robotadapt.validation import ConfigError

SHORT = ["simulation.t_final=0.2"]


def scenario(extra: list[str] | None = None):
    return load("example-6.3.1", SHORT + (extra or []))


def table_text(folder: Path) -> str:
    return (folder / "runs.jsonl").read_text()


def test_grid_values_and_random_bounds_parse_as_toml():
    assert parse_grid("controller.Kv=5,10,20") == ("controller.Kv", [5, 10, 20])
    assert parse_grid("plant.phi=[0.8,2.3],[1,2]") == ("plant.phi", [[0.8, 2.3], [1, 2]])
    assert parse_grid("simulation.method='rk4','RK45'") == ("simulation.method", ["rk4", "RK45"])
    assert parse_random("controller.Kv=5:20") == ("controller.Kv", 5.0, 20.0)
    assert parse_random("plant.phi=[0.6,2]:[1,2.6]") == ("plant.phi", [0.6, 2.0], [1.0, 2.6])
    for bad in ("controller.Kv", "Kv=5,10", "controller.Kv=", "controller.Kv=5,,10", "controller.=1"):
        with pytest.raises(ConfigError, match=r"^--grid: expected section\.key=v1,v2"):
            parse_grid(bad)
    for bad in ("controller.Kv=5", "controller.Kv=a:b", "Kv=1:2"):
        with pytest.raises(ConfigError, match=r"^--random: expected section\.key=lo:hi"):
            parse_random(bad)
    with pytest.raises(ConfigError, match=r"lo ≤ hi"):
        parse_random("controller.Kv=20:5")


def test_points_are_grid_times_draws_with_seeds_from_the_point():
    sw = make_sweep(scenario(), ["controller.Lam=1,2.5", "controller.Gamma=10,20,40"], ["plant.phi=[0.6,2]:[1,2.6]"],
                    n=4, seed=7)
    points = list(sw.points())
    assert len(sw) == len(points) == 2 * 3 * 4
    assert [p.run for p in points] == list(range(24))
    assert points[5].inputs["controller.Lam"] == 1 and points[5].inputs["controller.Gamma"] == 20  # axis order
    phis = np.array([p.inputs["plant.phi"] for p in points])
    assert np.all((phis >= [0.6, 2.0]) & (phis <= [1.0, 2.6]))
    assert len({p.seed for p in points}) == 24
    # deterministic, and each run's draw depends on its own point only: another grid around it changes nothing
    assert list(make_sweep(scenario(), ["controller.Lam=1,2.5", "controller.Gamma=10,20,40"],
                           ["plant.phi=[0.6,2]:[1,2.6]"], n=4, seed=7).points()) == points
    other = make_sweep(scenario(), ["controller.Lam=2.5", "controller.Gamma=20,80"], ["plant.phi=[0.6,2]:[1,2.6]"],
                       n=4, seed=7)
    same_point = next(p for p in other.points() if p.inputs["controller.Gamma"] == 20 and p.run % 4 == 1)
    original = next(p for p in points if p.inputs["controller.Lam"] == 2.5 and p.inputs["controller.Gamma"] == 20
                    and p.run % 4 == 1)
    assert (same_point.seed, same_point.inputs) == (original.seed, original.inputs)
    assert original.seed == seed_of({"controller.Lam": 2.5, "controller.Gamma": 20}, 1, 7)
    assert seed_of({"controller.Lam": 2.5, "controller.Gamma": 20}, 1, 8) != original.seed


def test_sweep_arguments_are_checked_before_anything_runs():
    s = scenario()
    with pytest.raises(ConfigError, match=r"^--grid: controller\.Kx=1 does not build: controller\.Kx: unknown key"):
        make_sweep(s, ["controller.Kx=1,2"])
    with pytest.raises(ConfigError, match=r"^--random: controller\.Kv=-5\.0 does not build: .*positive definite"):
        make_sweep(s, random=["controller.Kv=-5:5"])
    with pytest.raises(ConfigError, match=r"^--grid: controller\.Kv is swept twice"):
        make_sweep(s, ["controller.Kv=1,2"], ["controller.Kv=1:2"])
    with pytest.raises(ConfigError, match=r"^--n: draws per grid point need a --random key"):
        make_sweep(s, ["controller.Kv=1,2"], n=3)
    with pytest.raises(ConfigError, match=r"^--grid: give at least one"):
        make_sweep(s)


def test_rows_are_the_metrics_of_single_runs(tmp_path):
    """A vectorized chunk gives, per run, the metrics `robotadapt run` computes for that scenario (states logged
    every `log_every(...)` steps), with the run, its seed and its swept values."""
    s = scenario()
    sw = make_sweep(s, ["controller.phi_hat0=[0,0],[0.5,2]"], ["plant.phi=[0.6,2]:[1,2.6]"], n=2)
    report = run_sweep(sw, tmp_path, workers=1)
    assert report.computed == 4 and report.how.startswith("batched (simulate_batch")
    rows = read_table(tmp_path / "runs.jsonl")
    assert list(rows) == [0, 1, 2, 3]
    point = list(sw.points())[3]
    variant = load("example-6.3.1", SHORT + [f"controller.phi_hat0={point.inputs['controller.phi_hat0']}",
                                            f"plant.phi={point.inputs['plant.phi']}"])
    st = variant.setup
    single = metrics(simulate(st.plant, st.controller, st.trajectory, t_final=st.t_final, integrator=st.integrator,
                              log_every=log_every(st)))
    row = rows[3]
    assert (row["run"], row["seed"], row["controller.phi_hat0"], row["plant.phi"]) == (3, point.seed, [0.5, 2],
                                                                                        point.inputs["plant.phi"])
    assert single.pop("wall_time_s") > 0 and "wall_time_s" not in row
    for key, value in single.items():
        if value is None or isinstance(value, str | bool) or key in ("param_names", "consistency_parts"):
            assert row[key] == value, key
        else:
            np.testing.assert_allclose(row[key], value, rtol=1e-11, atol=1e-13, err_msg=key)


def test_sampled_data_runs_are_vectorized_and_each_row_is_its_single_run(tmp_path):
    """`robotadapt sweep example-6.3.1 --control-period 0.002 --random controller.Kv=5:20`: the chunk runs batched and
    compiled (one program mapped over the runs; before issue 23 "simulate Sampled runs one by one"), and a row's
    metrics equal those of the numpy single run with its K_v to 1e-9."""
    from robotadapt.sim import Sampled

    s = scenario(["simulation.control_period=0.002", "simulation.backend='jax'"])
    sw = make_sweep(s, [], ["controller.Kv=5:20"], n=3)
    report = run_sweep(sw, tmp_path, workers=1)
    assert report.computed == 3 and report.how == "batched (simulate_batch, backend jax)"
    rows = read_table(tmp_path / "runs.jsonl")
    for point in sw.points():
        st = load("example-6.3.1", SHORT + ["simulation.control_period=0.002",
                                            f"controller.Kv={point.inputs['controller.Kv']!r}"]).setup
        single = metrics(simulate(st.plant, st.controller, st.trajectory, t_final=st.t_final,
                                  integrator=Sampled(0.002, backend="numpy"), log_every=log_every(st)))
        row = rows[point.run]
        assert row["passivity_form"] == "tick sum" and row["status"] == "ok"
        for key in ("rms_error_norm", "final_phi_hat", "passivity_min", "ise", "control_energy"):
            np.testing.assert_allclose(row[key], single[key], rtol=1e-9, atol=1e-12, err_msg=key)


def test_keys_that_do_not_batch_run_scenario_by_scenario(tmp_path):
    sw = make_sweep(scenario(), ["robot.l2=0.9,1.1"])
    report = run_sweep(sw, tmp_path, workers=1)
    assert report.how.startswith("one scenario per run (plant.model.l2: differs between runs")
    assert [row["status"] for row in report.rows] == ["ok", "ok"]
    assert report.rows[0]["final_abs_error"] != report.rows[1]["final_abs_error"]


def test_a_point_that_does_not_build_gets_an_invalid_row():
    s = scenario()
    rows, _ = run_chunk((s.data, [Point(0, 1, {"controller.Kv": 10.0}), Point(1, 2, {"controller.Kv": -1.0})]))
    assert rows[0]["status"] == "ok"
    assert rows[1]["status"].startswith("invalid: controller.Kv: must be positive definite")


def test_an_interrupted_sweep_resumes_and_gives_the_uninterrupted_table(tmp_path, monkeypatch):
    """Chunks of 2 runs. The sweep is stopped (Ctrl-C) as its third chunk starts, and its last append is torn by a
    crash; the rerun drops the torn line, simulates only what is missing and is stopped again; the third run completes.
    The final table is the one an uninterrupted sweep writes, byte for byte, and is sorted by run whatever order the
    chunks finished in."""
    monkeypatch.setattr(sweep_module, "MAX_CHUNK", 2)
    sw = make_sweep(scenario(), ["controller.phi_hat0=[0,0],[0.5,2]"], ["plant.phi=[0.6,2]:[1,2.6]"], n=5)
    whole = run_sweep(sw, tmp_path / "whole", workers=1)
    assert whole.computed == 10
    folder, table = tmp_path / "resumed", tmp_path / "resumed" / "runs.jsonl"
    calls = []

    def interrupted(job):
        calls.append(job)
        if len(calls) % 3 == 0:
            raise KeyboardInterrupt
        return run_chunk(job)

    monkeypatch.setattr(sweep_module, "run_chunk", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(sw, folder, workers=1)
    assert len(read_table(table)) == 4
    with table.open("a") as f:
        f.write('{"run": 7, "seed": 1, "status": "o')  # a crash in the middle of an append
    with pytest.raises(KeyboardInterrupt):
        run_sweep(sw, folder, workers=1)
    assert sorted(read_table(table)) == [0, 1, 2, 3, 4, 5, 6, 7]
    monkeypatch.setattr(sweep_module, "run_chunk", run_chunk)
    assert run_sweep(sw, folder, workers=1).computed == 2
    assert table_text(folder) == table_text(tmp_path / "whole")
    lines = table_text(folder).splitlines(keepends=True)
    table.write_text("".join(lines[5:] + lines[:5]))  # rows as chunks finishing out of order leave them
    assert run_sweep(sw, folder, workers=1).computed == 0
    assert table_text(folder) == table_text(tmp_path / "whole")


def test_another_sweep_into_the_same_folder_is_refused(tmp_path):
    run_sweep(make_sweep(scenario(), ["controller.phi_hat0=[0,0],[0.5,2]"]), tmp_path, workers=1)
    with pytest.raises(ConfigError, match=r"^--out: .* holds another sweep"):
        run_sweep(make_sweep(scenario(), ["controller.phi_hat0=[0,0],[0.5,3]"]), tmp_path, workers=1)


def test_dask_local_cluster_and_local_processes_give_the_same_table(tmp_path):
    distributed = pytest.importorskip("dask.distributed", reason="the [dist] extra (dask, distributed) is not installed")
    sw = make_sweep(scenario(), ["controller.phi_hat0=[0,0],[0.5,2]"], ["plant.phi=[0.6,2]:[1,2.6]"], n=3)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        on_dask = run_sweep(sw, tmp_path / "dask", scheduler=cluster.scheduler_address)
    local = run_sweep(sw, tmp_path / "local", workers=2)
    assert on_dask.computed == local.computed == 6
    assert table_text(tmp_path / "dask") == table_text(tmp_path / "local")


def test_a_bad_scheduler_address_is_one_clear_error(tmp_path):
    pytest.importorskip("dask.distributed", reason="the [dist] extra (dask, distributed) is not installed")
    sw = make_sweep(scenario(), ["controller.phi_hat0=[0,0],[0.5,2]"])
    with pytest.raises(ConfigError, match=r"^--scheduler: cannot reach 'scheduler-host': missing port number"):
        run_sweep(sw, tmp_path, scheduler="scheduler-host")


def test_cli_sweep_writes_table_manifest_and_figure(tmp_path, capsys):
    out = tmp_path / "sw"
    code = main(["sweep", "example-6.3.1", "--t-final", "0.2", "--grid", "controller.phi_hat0=[0,0],[0.5,2]", "--random",
                 "plant.phi=[0.6,2]:[1,2.6]", "--n", "3", "--workers", "1", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    assert "sweep example-6.3.1: 6 runs (6 now, 0 already in the table)" in printed
    assert "6 ok, 0 not finished; rms_error_norm: best" in printed
    assert {p.name for p in out.iterdir()} == {"runs.jsonl", "sweep.json", "sweep.png"}
    manifest = json.loads((out / "sweep.json").read_text())
    assert manifest["grid"] == {"controller.phi_hat0": [[0, 0], [0.5, 2]]} and manifest["runs"] == 6
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("args, message", [
    (["--grid", "controller.Kv"], r"--grid: expected section\.key=v1,v2"),
    (["--grid", "controller.Kx=1,2"], r"--grid: controller\.Kx=1 does not build: controller\.Kx: unknown key"),
    (["--random", "controller.Kv=5"], r"--random: expected section\.key=lo:hi"),
    (["--random", "controller.Kv=5:20", "--n", "0"], r"--n: must be a positive whole number"),
    (["--random", "controller.Kv=5:20", "--metric", "speed"], r"--metric: unknown metric 'speed'"),
    (["--random", "controller.Kv=5:20", "--workers", "0"], r"--workers: must be at least 1"),
])
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, args, message):
    code = main(["sweep", "example-6.3.1", "--t-final", "0.2", "--out", str(tmp_path / "sw"), *args])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("robotadapt: error: ")
    assert re.match(message, err.removeprefix("robotadapt: error: ")), err
