"""docs/own-arm.md runs as written (tests/doc_pages.py), through the front door only, and says what it prints: the DH
table and the URDF give one arm, the digital run's warnings, the files written, the scenario equal to the Python run."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from doc_pages import blocks, run_page

pytest.importorskip("pinocchio")  # the page's URDF step (the `urdf` extra)
PAGE = Path(__file__).resolve().parents[1] / "docs" / "own-arm.md"
QUOTED = re.compile(r"(RMS ‖e‖ = |base-parameter error → |peak \|τ\| = )(\d+(?:\.\d+)?)")


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[str], Path]:
    folder = tmp_path_factory.mktemp("own-arm")
    return run_page(PAGE, folder).splitlines(), folder


def test_the_page_uses_the_front_door_only():
    code = "\n".join(c for lang, c in blocks(PAGE) if lang == "python")
    imports = re.findall(r"^(?:from|import) (\S+)", code, re.M)
    assert set(imports) <= {"numpy", "robotadapt", "pathlib", "robotadapt.analysis.metrics"}, imports


def test_every_number_the_page_prints_is_the_one_it_quotes(page):
    lines, _ = page
    printed = {m.group(0) for line in lines for m in QUOTED.finditer(line)}
    text = PAGE.read_text(encoding="utf-8")
    prose = {m.group(0) for m in QUOTED.finditer(text[text.index("With a 60 N·m limit"):])}
    assert prose and prose <= printed, f"quoted but not printed: {prose - printed}"


def test_the_dh_table_and_the_urdf_are_one_arm(page):
    lines, _ = page
    dh, urdf = (next(line for line in lines if line.startswith(f"{name}: M(q)")) for name in ("dh", "urdf"))
    assert dh.split(":", 1)[1] == urdf.split(":", 1)[1]


def test_the_saturated_run_is_warned_about_and_the_other_is_not(page):
    lines, _ = page
    assert "60 N·m: no warnings" in lines
    warned = next(line for line in lines if line.startswith("40 N·m: wind-up: the torque sat on its limit"))
    assert "Lyapunov growth" in warned


def test_the_files_and_the_scenario(page):
    lines, folder = page
    assert sorted(p.name for p in (folder / "results/my-arm").iterdir()) == [
        "metrics.json", "parameters.png", "result.npz", "torques.png", "tracking_error.png"]
    assert all((folder / "results/my-arm-40" / f"{f}.pdf").read_bytes().startswith(b"%PDF")
               for f in ("parameters", "torques", "tracking_error"))
    scenario = json.loads((folder / "results/my-arm-scenario/metrics.json").read_text())
    python = next(line for line in lines if line.startswith("1 kHz, 60 N·m: ok"))
    assert f"RMS ‖e‖ = {scenario['rms_error_norm']:.3g} rad" in python
    assert f"base-parameter error → {scenario['final_base_phi_error_relative']:.3g}" in python
    assert (folder / "results/my-arm-scenario/torques.svg").exists()
