"""A newcomer's first day (issue "A newcomer's first day, third pass"): the pages one can find, a scenario without an
empty [plant], the lineup's names in `compare --help`."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from robotadapt.cli import main
from robotadapt.studies.compare import contenders

ROOT = Path(__file__).resolve().parents[1]


def test_the_own_arm_page_is_linked_from_the_readme_and_the_docs_home() -> None:
    assert "(docs/own-arm.md)" in (ROOT / "README.md").read_text()
    assert "(own-arm.md)" in (ROOT / "docs" / "index.md").read_text()


def test_the_own_arm_pages_cross_references_are_links() -> None:
    text = (ROOT / "docs" / "own-arm.md").read_text()
    plain = [m.group(0) for m in re.finditer(r"(?<!\[)docs/[a-z0-9_-]+\.md(#[a-z0-9_-]+)?(?!\]\()", text)]
    assert not plain, f"plain-text references: {plain}"
    assert len(re.findall(r"\]\([a-z0-9_-]+\.md", text)) >= 5


def test_a_scenario_needs_no_plant_section_when_every_plant_key_has_a_default(tmp_path: Path,
                                                                                capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "arm.toml"
    path.write_text('[robot]\nkind = "planar"\nn_links = 2\n\n[trajectory]\nkind = "sinusoid"\n\n[controller]\n'
                    'kind = "slotine_li"\nLam = 2.5\nKv = 10\nGamma = 20\n\n[simulation]\nt_final = 0.05\n')
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    assert (tmp_path / "out" / "metrics.json").is_file()


def test_a_missing_true_phi_without_a_plant_section_is_one_line_naming_the_key(tmp_path: Path,
                                                                                 capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "arm.toml"
    path.write_text('[robot]\nkind = "two_link"\n\n[trajectory]\nkind = "sinusoid"\n\n[controller]\n'
                    'kind = "slotine_li"\nLam = 2.5\nKv = 10\nGamma = 20\nphi_hat0 = [0, 0]\n\n[simulation]\n'
                    't_final = 0.05\n')
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-plots"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plant.phi" in err[0]


def test_compare_help_lists_every_lineup_name(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["compare", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    names = list(contenders())
    assert len(names) >= 12
    listed = text.split("names of the lineup:")[1]
    for name in names:
        assert re.search(rf"\b{name}\b", listed.replace(",", " ")), name


def test_no_lyapunov_growth_warning_for_a_law_that_holds_its_estimate() -> None:
    from robotadapt.analysis.metrics import health_warnings, metrics
    from robotadapt.studies.scenarios import load

    held = metrics(load("example-6.3.1", ["simulation.t_final=0.5", 'controller.adaptation="none"']).run())
    adapting = metrics(load("example-6.3.1", ["simulation.t_final=0.5"]).run())
    assert "held" in held["lyapunov_not_applicable"] and "lyapunov_not_applicable" not in adapting
    grown = {**adapting, "V_initial": 1.0, "V_final": 20.0}  # V grew twentyfold
    assert any("Lyapunov growth" in w for w in health_warnings(grown))
    grown["lyapunov_not_applicable"] = held["lyapunov_not_applicable"]
    assert not any("Lyapunov growth" in w for w in health_warnings(grown))


def test_fixed_estimate_baselines_compensate_with_the_nominal_model() -> None:
    import numpy as np

    from robotadapt.studies.compare import lineup
    from robotadapt.studies.scenarios import load

    base = load("example-6.3.1")
    entries, _ = lineup(base, ["pd_gravity", "computed_torque", "slotine_li"])
    phi_hat0 = {e.name: np.asarray(e.scenario.data["controller"]["phi_hat0"]) for e in entries}
    truth = np.asarray(base.setup.plant.phi)  # the book's arm has no nominal values: its own
    np.testing.assert_array_equal(phi_hat0["pd_gravity"], truth)
    np.testing.assert_array_equal(phi_hat0["computed_torque"], truth)
    np.testing.assert_array_equal(phi_hat0["slotine_li"], [0.0, 0.0])  # the adaptive laws' common start
    assert any("nominal" in n or "true φ" in n for e in entries if e.name == "pd_gravity" for n in [e.note])


def test_a_baseline_on_a_urdf_arm_takes_the_urdfs_values() -> None:
    import numpy as np

    from robotadapt.studies.compare import lineup
    from robotadapt.studies.scenarios import load

    base = load("panda-slotine-li")
    entries, _ = lineup(base, ["pd_gravity"])
    np.testing.assert_allclose(entries[0].scenario.data["controller"]["phi_hat0"],
                               base.setup.controller.model.default_phi)
    assert "nominal" in entries[0].note


def test_every_row_of_the_keys_page_is_one_row_of_five_cells() -> None:
    import sys

    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import generate
    finally:
        sys.path.remove(str(ROOT / "docs"))
    page = generate.keys_page()
    rows = [line for line in page.splitlines() if line.startswith("|")]
    assert rows
    for line in rows:  # a multi-line default (dh's g) once broke its table into rows "0.0,", "-9.81,"
        assert len(re.findall(r"(?<!\\)\|", line)) == 6, line
    fourier = page[page.index('### kind = "fourier"'):]
    fourier = fourier[: fourier.index("\n### ")]
    assert "composite" not in fourier and "| `b` | —" not in fourier
    assert "default: the trajectory's" not in fourier


def test_the_planar_and_dh_arms_on_the_kinematic_tree_need_no_sympy(tmp_path: Path) -> None:
    import subprocess
    import sys

    code = ("import sys\n"
            "class Block:\n"
            "    def find_spec(self, name, path, target=None):\n"
            "        if name.split('.')[0] == 'sympy':\n"
            "            raise ModuleNotFoundError('No module named sympy')\n"
            "sys.meta_path.insert(0, Block())\n"
            "import robotadapt as ra\n"
            "arm = ra.planar(3, lengths=[1.0, 0.8, 0.5], masses=[2.0, 1.0, 0.5])\n"
            "tree = ra.dh_arm([{'a': 1.0, 'm': 1.0}, {'a': 0.5, 'm': 0.5}])\n"
            "print(type(arm).__name__, arm.p, type(tree).__name__)\n")
    env = {**__import__("os").environ, "ROBOTADAPT_CACHE": str(tmp_path)}  # nothing derived before
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr[-500:]
    assert out.stdout.split() == ["KinematicTree", "30", "KinematicTree"]


def test_export_check_builds_the_harness_and_compares_it_with_the_python_step(tmp_path: Path,
                                                                              capsys: pytest.CaptureFixture) -> None:
    import json

    from robotadapt.cli.export_cmd import _check
    from robotadapt.native.build import compiler
    from robotadapt.validation import ConfigError

    if compiler() is None:
        pytest.skip("no C compiler")
    assert main(["export", "example-6.3.1", "--out", str(tmp_path / "c"), "--check", "300"]) == 0
    record = json.loads((tmp_path / "c" / "export.json").read_text())
    assert record["check"]["ticks"] == 300 and record["check"]["max_rel_difference"] <= 1e-12
    assert "checked:" in capsys.readouterr().out
    wrong = tmp_path / "wrong"  # a harness that answers τ = 0 on every line
    wrong.write_text("#!/bin/sh\nwhile read line; do echo 0 0; done\n")
    wrong.chmod(0o755)
    with pytest.raises(ConfigError, match="differs from the Python step"):
        _check("example-6.3.1", [], wrong, 50)


def test_compare_variants_side_by_side_equal_their_own_runs(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import json

    from robotadapt.analysis.metrics import metrics
    from robotadapt.studies.scenarios import load

    out = tmp_path / "v"
    assert main(["compare", "example-6.3.1", "--t-final", "0.5", "--out", str(out),
                 "--variant", 'controller.adaptation="none"', "--variant", "controller.Kv=20;controller.Lam=5"]) == 0
    rows = json.loads((out / "comparison.json").read_text())["rows"]
    assert [r["controller"] for r in rows] == ["as written", 'controller.adaptation="none"',
                                               "controller.Kv=20; controller.Lam=5"]
    for row, extra in zip(rows, ([], ['controller.adaptation="none"'], ["controller.Kv=20", "controller.Lam=5"]),
                          strict=True):
        alone = metrics(load("example-6.3.1", ["simulation.t_final=0.5", *extra]).run())
        assert row["rms_error_norm"] == pytest.approx(alone["rms_error_norm"], rel=1e-12)
    assert main(["compare", "example-6.3.1", "--variant", "controller.Kv=20", "--fair", "--max-torque", "100"]) == 2


def test_list_marks_the_extras_a_scenario_needs(capsys: pytest.CaptureFixture) -> None:
    assert main(["list"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines()}
    assert lines["panda-slotine-li"].endswith("[needs: urdf]")
    assert lines["panda-mujoco"].endswith("[needs: urdf, mujoco]")
    assert "[needs" not in lines["example-6.3.1"]


def test_the_summary_of_a_law_without_an_estimate_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["run", "example-7.2.2", "--t-final", "0.2", "--no-plots", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "  no parameter estimate" in out.splitlines() and "= []" not in out


def test_the_first_command_installs_every_extra_a_command_asks_for():
    """Item 1: after `make demo`, no command of the README or the guides asks for an install. Every extra that the
    package names in its messages (`robotadapt[X]`) is in `[all]`, and the target `make demo` depends on installs
    `[all]`."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    everything = project["optional-dependencies"]["all"]
    assert len(everything) == 1 and everything[0].startswith("robotadapt[")
    included = set(everything[0][len("robotadapt["):-1].split(","))
    named = set()
    for path in (ROOT / "src").rglob("*.py"):
        named |= set(re.findall(r"robotadapt\[([a-z]+)\]", path.read_text()))
    assert named - {"jax"} <= included, named - included
    assert included <= set(project["optional-dependencies"]) - {"all", "dev"}
    makefile = (ROOT / "Makefile").read_text()
    prerequisite = re.search(r"^demo: (\S+)", makefile, flags=re.MULTILINE)
    assert prerequisite
    recipe = re.search(rf"^{re.escape(prerequisite.group(1))}:.*\n\t(.*)\n", makefile, flags=re.MULTILINE)
    assert recipe and '-e ".[all]"' in recipe.group(1)


def test_identify_without_cvxpy_says_so_before_any_work(monkeypatch, capsys, tmp_path):
    """Item 1: a missing extra is found before the data is read (the log here does not even exist)."""
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "cvxpy" else real(name, *a))
    code = main(["identify", str(tmp_path / "absent.csv"), "--robot", "example-6.3.1", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "--estimate" in err[0] and "robotadapt[identify]" in err[0] and "absent" not in err[0]
