"""The `robotadapt` command line: `list`, `run`, and bad input (exit 2, one line on stderr naming the field, no traceback).

Most cases call `robotadapt.cli.main(argv)` in-process (an uncaught exception would fail the test just as a traceback
would); a few go through `python -m robotadapt` to check the real process: exit code, streams, files.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.studies.scenarios import available

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

NPZ_KEYS = ("t", "q", "dq", "q_des", "tau", "phi_hat", "V")
METRIC_KEYS = ("final_abs_error", "rms_error", "max_abs_torque", "final_phi_hat", "status")
FIGURES = ("tracking_error.png", "parameters.png", "torques.png")


def cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "robotadapt", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300)


def one_error_line(err: str) -> str:
    """stderr of a bad-input run: exactly one line, the CLI's error prefix, no traceback."""
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("robotadapt: error: "), lines[0]
    return lines[0]


# ---------------------------------------------------------------------------------------------------------------------
# list


def test_list_shows_every_packaged_scenario_with_its_description():
    proc = cli("list")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    lines = proc.stdout.splitlines()
    scenarios = available()
    assert len(lines) == len(scenarios)
    for name, description in scenarios.items():
        line = next(line for line in lines if line.split()[0] == name)
        assert description in line
    for name in ("example-6.2.1", "example-6.3.1", "example-6.5.1", "example-6.5.2a", "example-6.5.2b", "problem-6.3-1"):
        assert name in scenarios


# ---------------------------------------------------------------------------------------------------------------------
# run


def test_run_writes_every_file(tmp_path):
    out = tmp_path / "run"
    proc = cli("run", "example-6.3.1", "--out", str(out), "--t-final", "1")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "example-6.3.1" in proc.stdout
    for name in ("result.npz", "metrics.json", "scenario.toml", *FIGURES):
        assert (out / name).is_file(), name
    with np.load(out / "result.npz") as npz:
        assert set(NPZ_KEYS) <= set(npz.files)
        t = npz["t"]
        assert t[0] == 0.0 and t[-1] == pytest.approx(1.0)
        assert t.shape == (1001,)  # dt = 1e-3 from the scenario
        for key in NPZ_KEYS[1:]:
            assert npz[key].shape[0] == t.shape[0], key
        assert npz["q"].shape == (1001, 2) and npz["phi_hat"].shape == (1001, 2)
        metrics = json.loads((out / "metrics.json").read_text())
        np.testing.assert_allclose(metrics["final_abs_error"], np.abs(npz["q_des"][-1] - npz["q"][-1]))
        np.testing.assert_allclose(metrics["final_phi_hat"], npz["phi_hat"][-1])
        np.testing.assert_allclose(metrics["max_abs_torque"], np.max(np.abs(npz["tau"]), axis=0))
    assert set(METRIC_KEYS) <= set(metrics)
    assert metrics["status"] == "ok"
    saved = tomllib.loads((out / "scenario.toml").read_text())
    assert saved["simulation"]["t_final"] == 1.0  # the resolved scenario, with the override
    assert saved["controller"]["kind"] == "slotine_li"
    for name in FIGURES:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_set_changes_the_saved_scenario_and_the_result(tmp_path, capsys):
    """With φ̂(0) = 0 and q(0) = q̇(0) = 0, τ(0) = Y φ̂ + K_v r = K_v r(0) with r(0) = q̇_d(0) = (1, 1) (Example 6.3.1):
    τ(0) = (10, 10) as shipped and (20, 20) with --set controller.Kv=20."""
    base, changed = tmp_path / "base", tmp_path / "kv20"
    assert main(["run", "example-6.3.1", "--out", str(base), "--t-final", "0.5", "--no-plots"]) == 0
    assert main(["run", "example-6.3.1", "--out", str(changed), "--t-final", "0.5", "--no-plots",
                 "--set", "controller.Kv=20"]) == 0
    capsys.readouterr()
    assert tomllib.loads((base / "scenario.toml").read_text())["controller"]["Kv"] == 10
    assert tomllib.loads((changed / "scenario.toml").read_text())["controller"]["Kv"] == 20
    with np.load(base / "result.npz") as a, np.load(changed / "result.npz") as b:
        np.testing.assert_allclose(a["tau"][0], [10.0, 10.0], rtol=1e-12)
        np.testing.assert_allclose(b["tau"][0], [20.0, 20.0], rtol=1e-12)
        assert not np.allclose(a["q"][-1], b["q"][-1], rtol=0, atol=1e-9)
    assert not (base / "tracking_error.png").exists()  # --no-plots


def test_run_accepts_a_scenario_file_and_dt(tmp_path, capsys):
    from robotadapt.studies.scenarios import load

    path = tmp_path / "mine.toml"
    path.write_text(load("example-6.5.1").text)
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--t-final", "0.2", "--dt", "0.01", "--no-plots"]) == 0
    assert "mine" in capsys.readouterr().out
    with np.load(out / "result.npz") as npz:
        np.testing.assert_allclose(npz["t"], 0.01 * np.arange(21), atol=1e-12)


def test_a_diverging_run_exits_1_and_keeps_its_files(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", "example-6.3.1", "--out", str(out), "--t-final", "2", "--no-plots",
                 "--set", "simulation.max_state=0.5"])
    assert code == 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"].startswith("diverged at t=")
    assert metrics["t_end"] < 2.0


# ---------------------------------------------------------------------------------------------------------------------
# bad input


def _write(tmp_path: Path, name: str, content: str | bytes) -> str:
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return str(path)


def _without_controller(tmp_path: Path) -> str:
    from robotadapt.studies.scenarios import load

    data = tomllib.loads(load("example-6.3.1").text)
    del data["controller"]
    import tomli_w

    return _write(tmp_path, "no_controller.toml", tomli_w.dumps(data))


def _blocked_out(tmp_path: Path) -> str:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    return str(blocker / "out")


# (id, argv after "run" built from tmp_path, text the error line must contain)
BAD = [
    ("malformed-toml", lambda p: [_write(p, "bad.toml", "[robot\nkind = ")], "scenario"),
    ("empty-file", lambda p: [_write(p, "empty.toml", "")], "robot"),
    ("random-bytes", lambda p: [_write(p, "noise.toml", b"\xff\xfe\x00\x9c" + np.random.default_rng(0).bytes(200))],
     "scenario"),
    ("unknown-scenario", lambda p: ["example-9.9.9"], "example-9.9.9"),
    ("unknown-set-key", lambda p: ["example-6.3.1", "--set", "controller.Kw=20"], "controller.Kw"),
    ("unknown-set-section", lambda p: ["example-6.3.1", "--set", "control.Kv=20"], "control"),
    ("set-without-equals", lambda p: ["example-6.3.1", "--set", "controller.Kv"], "controller.Kv"),
    ("negative-gain", lambda p: ["example-6.3.1", "--set", "controller.Kv=-1"], "controller.Kv"),
    ("indefinite-gain", lambda p: ["example-6.3.1", "--set", "controller.Kv=[[1, 2], [2, 1]]"], "controller.Kv"),
    ("asymmetric-gain", lambda p: ["example-6.3.1", "--set", "controller.Lam=[[1, 2], [0, 1]]"], "controller.Lam"),
    ("nan-gain", lambda p: ["example-6.3.1", "--set", "controller.Kv=nan"], "controller.Kv"),
    ("nan-estimate", lambda p: ["example-6.3.1", "--set", "controller.phi_hat0=[0, nan]"], "controller.phi_hat0"),
    ("wrong-shape-phi", lambda p: ["example-6.3.1", "--set", "plant.phi=[1]"], "plant.phi"),
    ("wrong-shape-q0", lambda p: ["example-6.3.1", "--set", "plant.q0=[0, 0, 0]"], "plant.q0"),
    ("negative-mass", lambda p: ["example-6.3.1", "--set", "plant.phi=[-0.8, 2.3]"], "plant.phi"),
    ("negative-dt", lambda p: ["example-6.3.1", "--dt", "-0.001"], "simulation.dt"),
    ("tiny-dt", lambda p: ["example-6.3.1", "--t-final", "1", "--dt", "1e-12"], "simulation.dt"),
    ("zero-t-final", lambda p: ["example-6.3.1", "--t-final", "0"], "simulation.t_final"),
    ("unknown-controller-kind", lambda p: ["example-6.3.1", "--set", "controller.kind=magic"], "controller.kind"),
    ("unknown-method", lambda p: ["example-6.3.1", "--set", "simulation.method=Euler"], "simulation.method"),
    ("string-gain", lambda p: ["example-6.3.1", "--set", "controller.Kv=fast"], "controller.Kv"),
    ("missing-section", lambda p: [_without_controller(p)], "controller"),
    ("unwritable-out", lambda p: ["example-6.3.1", "--t-final", "0.01", "--no-plots", "--out", _blocked_out(p)],
     "--out"),
]




@pytest.mark.parametrize("make_args, field", [pytest.param(f, field, id=name)
                                              for name, f, field in BAD])
def test_bad_input_exits_2_with_one_line_naming_the_field(tmp_path, capsys, make_args, field):
    args = ["run", *make_args(tmp_path)]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "out")]
    code = main(args)
    captured = capsys.readouterr()
    assert code == 2, captured
    line = one_error_line(captured.err)
    assert field in line
    assert not (tmp_path / "out" / "result.npz").exists()


@pytest.mark.parametrize("args, field", [
    (["run", "example-6.3.1", "--set", "controller.Kv=[[1, 2], [2, 1]]"], "controller.Kv"),
    (["run", "no-such-scenario"], "no-such-scenario"),
])
def test_bad_input_through_the_real_process(tmp_path, args, field):
    proc = cli(*args, "--out", str(tmp_path / "out"))
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert field in one_error_line(proc.stderr)


# ---------------------------------------------------------------------------------------------------------------------
# the first hour: version, a result at the prompt, the book's name of a law


def test_version_option_prints_the_installed_version():
    """`robotadapt --version` reads the installed metadata (pyproject.toml's version, no copy of the number)."""
    import importlib.metadata

    proc = cli("--version")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"robotadapt {importlib.metadata.version('robotadapt')}"


def test_package_version_is_the_installed_metadata():
    import importlib.metadata

    import robotadapt

    assert robotadapt.__version__ == importlib.metadata.version("robotadapt")


def test_a_result_reads_in_a_few_lines_at_the_prompt():
    from robotadapt.studies.scenarios import load

    res = load("example-6.3.1", ["simulation.t_final=0.1"]).run()
    text = repr(res)
    assert len(text.splitlines()) < 10 and len(text) < 400, text
    for part in ("status='ok'", "101 samples", "0.1 s", "2 joints", "m1, m2", "final |e|"):
        assert part in text, (part, text)
    assert str(res) == text


def test_the_books_name_inertia_related_builds_the_slotine_li_law():
    """Table 6.3.1 calls Slotine–Li's law the inertia-related controller: both kind names build the one class, with
    the same gains; an unknown kind lists both names."""
    from robotadapt.controllers import InertiaRelated
    from robotadapt.studies.compare import lineup
    from robotadapt.studies.scenarios import load
    from robotadapt.validation import ConfigError

    ours = load("example-6.3.1").setup.controller
    book = load("example-6.3.1", ["controller.kind='inertia_related'"]).setup.controller
    assert type(ours) is type(book) is InertiaRelated
    for name in ("Lam", "Kv", "Gamma", "phi_hat0"):
        np.testing.assert_array_equal(getattr(ours, name), getattr(book, name))
    entries, _ = lineup(load("example-6.3.1", ["controller.kind='inertia_related'"]))
    assert "scenario" not in [e.name for e in entries]  # it is the lineup's slotine_li, not another law
    with pytest.raises(ConfigError, match="inertia_related.*slotine_li"):
        load("example-6.3.1", ["controller.kind='magic'"])


def test_progress_bars_only_on_a_terminal(tmp_path):
    """A run long enough to show a progress bar (numpy, 4 s) prints none when stderr is a file or a pipe."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "robotadapt", "run", "example-6.3.1", "--backend", "numpy", "--t-final",
                           "4", "--no-plots", "--out", str(tmp_path)], capture_output=True, text=True, check=True)
    assert done.stderr == ""


def test_bare_robotadapt_lists_every_command_and_exits_0(capsys):
    """A newcomer's first call: the commands with their one-line help and where to start, not a usage error."""
    from robotadapt.cli import COMMANDS

    assert main([]) == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert f"\n    {name} " in out, name
    assert "robotadapt list" in out
