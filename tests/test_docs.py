"""The documentation: generated pages are current, the tutorial's code runs, the site builds with no warning."""

import importlib.util
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _generator():
    spec = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


DOCTESTED = ["robotadapt.sim.batch", "robotadapt.sim.simulation"]


def test_every_module_with_docstring_examples_is_listed():
    src = ROOT / "src"
    found = sorted(".".join(p.relative_to(src).with_suffix("").parts) for p in (src / "robotadapt").rglob("*.py")
                   if ">>>" in p.read_text(encoding="utf-8"))
    assert found == sorted(DOCTESTED)


@pytest.mark.parametrize("name", DOCTESTED)
def test_docstring_examples_run(name):
    import doctest
    import importlib

    failed, attempted = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert attempted > 0 and failed == 0


@pytest.mark.parametrize("page", ["theory.md", "cli.md", "audit.md"])
def test_generated_pages_are_current(page):
    """Regenerate with `python docs/generate.py` when this fails."""
    assert (DOCS / page).read_text(encoding="utf-8") == _generator().PAGES[page](), f"docs/{page} is out of date"


def test_every_audit_case_is_a_clear_error():
    rows = [line for line in (DOCS / "audit.md").read_text(encoding="utf-8").splitlines() if line.startswith("| ")][1:]
    assert len(rows) == len(_generator().AUDIT)
    for row in rows:
        _, code, message = (cell.strip() for cell in row.strip("|").rsplit("|", 2))
        assert code == "2" and message.startswith("robotadapt: error: ") and "Traceback" not in message, row


def test_the_theory_map_names_importable_code():
    text = (DOCS / "theory.md").read_text(encoding="utf-8")
    for name in set(re.findall(r"`(robotadapt\.[\w.]+)`", text)):
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):  # the longest importable module, then attributes
            try:
                obj = __import__(".".join(parts[:cut]), fromlist=["_"])
                break
            except ModuleNotFoundError:
                continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)


def test_tutorial_code_runs_and_the_dead_zone_freezes_the_estimates(capsys):
    blocks = re.findall(r"```python\n(.*?)```", (DOCS / "tutorial.md").read_text(encoding="utf-8"), re.S)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "tutorial.md", "exec"), namespace)
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[0] for line in lines] == ["InertiaRelated", "DeadZoneSlotineLi"]
    ranges = [np.array([float(v) for v in re.findall(r"[\d.]+(?:e-?\d+)?", line.split("range after 10 s =")[1])])
              for line in lines]
    assert np.all(ranges[0] > 1.0) and np.all(ranges[1] < 1e-9)  # the dead zone stops the estimates wandering


@pytest.mark.skipif(shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None, reason="mkdocs not installed")
def test_site_builds_with_no_warning(tmp_path):
    mkdocs = str(Path(sys.executable).parent / "mkdocs")
    run = subprocess.run([mkdocs, "build", "--strict", "-q", "-d", str(tmp_path / "site")], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "site" / "tutorial" / "index.html").exists()
