"""docs/tutorial.md runs as written, in an empty folder, in fresh processes (tests/doc_pages.py), and says what it
prints: a user's controller is traceable, named from a scenario by `kind = "module:Class"`, run and swept by the CLI."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from doc_pages import run_page
from robotadapt.native.build import compiler

PAGE = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"
QUOTED = re.compile(r"(max \|e\| after 10 s|max ‖r‖ after 10 s|estimate range after 10 s) = (\[[^\]]*\]|\d+(?:\.\d+)?)")


@pytest.fixture(scope="module")
def printed(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    folder = tmp_path_factory.mktemp("tutorial")
    return run_page(PAGE, folder), folder


def test_every_number_the_tutorial_prints_is_the_one_it_quotes(printed):
    out, _ = printed
    said = {m.group(0) for m in QUOTED.finditer(PAGE.read_text(encoding="utf-8"))}
    shown = [m.group(0) for m in QUOTED.finditer(out)]
    assert len(shown) == 9, out
    assert set(shown) <= said, f"printed but not quoted: {set(shown) - said}"
    assert said <= set(shown), f"quoted but not printed: {said - set(shown)}"


def test_the_dead_zone_freezes_the_estimates_and_compiles(printed):
    out, _ = printed
    lines = out.splitlines()
    backend = "c" if compiler() else "jax"  # "auto": a single run in C where a compiler is present
    assert lines[0].startswith("InertiaRelated ") and f" {backend} " in lines[0]
    assert lines[1].startswith(f"DeadZoneSlotineLi 0.2 ok {backend} ") and lines[1].endswith("= [0.0, 0.0]")
    assert "DeadZoneSlotineLi is traceable" in out
    assert re.search(r"NumpyDeadZone is not traceable: simulation\.backend: NumpyDeadZone on TwoLinkArm cannot be "
                     r"compiled with JAX \(TracerArrayConversionError", out)


def test_the_scenario_names_the_users_class_and_the_cli_runs_and_sweeps_it(printed):
    out, folder = printed
    assert re.search(r"^dead-zone: ok; t = 20 s", out, re.M), out
    written = json.loads((folder / "results/dead-zone/metrics.json").read_text())
    assert written["status"] == "ok"
    assert (folder / "results/dead-zone/scenario.toml").read_text().count('kind = "deadzone:DeadZoneSlotineLi"') == 1
    assert "4 ok, 0 not finished" in out


def test_a_law_of_your_own_registers_itself_in_its_class(printed):
    out, _ = printed
    assert "registered: True True ['sign_robust', 'dead_zone', 'dcal', 'repetitive']" in out
    assert "in the lineup: Peterson & Narendra; gains: Example 6.3.1; δ = 0.2; from the scenario: Kv" in out
    text = PAGE.read_text(encoding="utf-8")
    assert "`registered: True True ['sign_robust', 'dead_zone', 'dcal', 'repetitive']`" in text
    assert "`in the lineup: Peterson & Narendra; gains: Example 6.3.1; δ = 0.2;\nfrom the scenario: Kv`" in text
