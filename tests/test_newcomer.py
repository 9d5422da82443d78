"""A newcomer's first minutes, scripted from the README alone, in a fresh clone: its first block's `make demo`, then
what the README says to do next — `source .venv/bin/activate`, bare `robotadapt`, `robotadapt list`, the Python
session — and the command-line block's first run. The slow test does it verbatim on a new `.venv`; the fast one runs
the same lines with this environment's `.venv` standing in for the one `make demo` would set up."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from doc_pages import blocks, run_page

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
needs_git = pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="no git checkout")


def first_commands() -> list[str]:
    """The README's first block: the two commands a newcomer types first."""
    lang, code = blocks(README)[0]
    assert lang == "sh"
    return [line.split("#")[0].strip() for line in code.splitlines() if line.strip()]


def clone(folder: Path) -> Path:
    """A fresh clone of this checkout's committed state."""
    subprocess.run(["git", "clone", "-q", str(ROOT), str(folder / "robotadapt")], check=True)
    return folder / "robotadapt"


def newcomer(repo: Path, bin_dir: Path) -> dict[str, subprocess.CompletedProcess]:
    """The README's next steps in `repo` with `bin_dir` activated (as `source .venv/bin/activate` does)."""
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "VIRTUAL_ENV": str(bin_dir.parent),
           "MPLBACKEND": "Agg"}
    python = next(code for lang, code in blocks(README) if lang == "python")
    cli = next(code for lang, code in blocks(README) if lang == "sh" and code.startswith("robotadapt list"))
    first_run = next(line.split("#")[0].strip() for line in cli.splitlines() if line.startswith("robotadapt run "))
    steps = {"bare": "robotadapt", "list": "robotadapt list", "python": f"python -c {shlex.quote(python)}",
             "run": first_run}
    return {name: subprocess.run(["sh", "-c", line], cwd=repo, env=env, capture_output=True, text=True, timeout=900)
            for name, line in steps.items()}


def check(done: dict[str, subprocess.CompletedProcess], repo: Path) -> None:
    assert done["bare"].returncode == 0 and re.search(r"^\s+run\s", done["bare"].stdout, re.M), done["bare"]
    assert {"run", "compare", "tune", "sweep", "pe", "gains", "list", "figures"} <= set(
        re.findall(r"^\s+(\w+)\s", done["bare"].stdout, re.M))
    assert done["list"].returncode == 0 and "example-6.3.1" in done["list"].stdout
    assert done["python"].returncode == 0, done["python"].stderr
    printed = re.match(r"ok \[([^\]]*)\]", done["python"].stdout)
    assert printed and max(map(float, printed.group(1).split())) < 1e-8, done["python"].stdout  # "ok, |e| ≈ 1e-10"
    assert done["run"].returncode == 0, done["run"].stderr
    out = repo / done["run"].args[2].split("--out")[1].split()[0]
    assert {"result.npz", "metrics.json", "scenario.toml", "tracking_error.png"} <= {p.name for p in out.iterdir()}


def test_the_readme_starts_with_make_demo_and_make_test():
    assert first_commands() == ["make demo", "make test"]
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^demo: \$\(VENV\)/\.core", makefile, re.M) and re.search(r"^test: ", makefile, re.M)
    text = README.read_text()
    assert "source .venv/bin/activate" in text and "bare\n`robotadapt` lists the commands" in text


@needs_git
def test_a_newcomer_follows_the_readme_in_a_fresh_clone(tmp_path):
    repo = clone(tmp_path)
    demo = re.search(r"^demo:.*\n\t(.*)", (repo / "Makefile").read_text(), re.M).group(1)  # what `make demo` runs
    bin_dir = Path(sys.executable).parent
    done = subprocess.run(["sh", "-c", demo.replace("$(BIN)", str(bin_dir))], cwd=repo, capture_output=True,
                          text=True, timeout=900, env={**os.environ, "MPLBACKEND": "Agg"})
    assert done.returncode == 0, done.stderr
    assert (repo / "results/example-6.3.1/tracking_error.png").exists()
    check(newcomer(repo, bin_dir), repo)


@pytest.mark.slow
@needs_git
@pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")
def test_a_newcomer_follows_the_readme_verbatim_on_a_new_venv(tmp_path):
    repo = clone(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if Path(p) != Path(sys.executable).parent)
    done = subprocess.run(["make", "demo"], cwd=repo, capture_output=True, text=True, timeout=1800,
                          env={**env, "MPLBACKEND": "Agg"})  # the machine's python3, as a newcomer has it
    assert done.returncode == 0, done.stdout + done.stderr
    assert (repo / "results/example-6.3.1/tracking_error.png").exists()
    check(newcomer(repo, repo / ".venv/bin"), repo)
    timings = first_day(repo, repo / ".venv/bin", tmp_path / "day")
    print("the newcomer's day, wall time (s):", {k: round(v, 1) for k, v in timings.items()})


NO_PLANT = """description = "my 3-link planar arm, its own parameters: no [plant] section"
[robot]
kind = "planar"
n_links = 3
lengths = [0.5, 0.4, 0.3]
masses = [3.0, 2.0, 1.0]
[trajectory]
kind = "sinusoid"
[controller]
kind = "slotine_li"
Lam = 5.0
Kv = 20.0
Gamma = 5.0
[simulation]
t_final = 2.0
"""


def first_day(repo: Path, bin_dir: Path, folder: Path) -> dict[str, float]:
    """The rest of a control engineer's first day (issue 43) after `make demo`, with nothing installed since: the own
    arm from Python (docs/own-arm.md as written) and from a file without `[plant]`, the Panda, identification from the
    Panda's log, a comparison and variants side by side. Each step must succeed; returns each step's wall time."""
    folder.mkdir()
    (folder / "no-plant.toml").write_text(NO_PLANT)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "VIRTUAL_ENV": str(bin_dir.parent),
           "MPLBACKEND": "Agg"}
    steps = {
        "own arm, file without [plant]": "robotadapt run no-plant.toml --out own",
        "the Panda": "robotadapt run panda-slotine-li --t-final 3 --out panda",
        "identify": "robotadapt identify panda/result.npz --robot panda-slotine-li --out ident",
        "compare": "robotadapt compare example-6.3.1 --t-final 2 --out cmp",
        "variants": "robotadapt compare problem-6.3-1 --t-final 2 --out var --variant 'controller.Gamma=5' "
                    "--variant 'controller.Gamma=50'",
    }
    timings = {}
    start = time.perf_counter()
    page = folder / "own-arm"
    page.mkdir()
    run_page(repo / "docs" / "own-arm.md", page, timeout=1800, python=bin_dir / "python")
    timings["own arm, docs/own-arm.md"] = time.perf_counter() - start
    for name, line in steps.items():
        start = time.perf_counter()
        done = subprocess.run(["sh", "-c", line], cwd=folder, env=env, capture_output=True, text=True, timeout=1800)
        timings[name] = time.perf_counter() - start
        assert done.returncode == 0, f"{name}: {line}\n{done.stdout}\n{done.stderr}"
        assert "pip install" not in done.stdout + done.stderr, (name, done.stderr)
    assert (folder / "ident" / "identified.json").exists() and (folder / "cmp" / "comparison.json").exists()
    return timings
