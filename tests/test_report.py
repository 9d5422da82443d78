"""Reports: the gallery of the book's examples (`robotadapt figures`), the comparison of controllers (`robotadapt
compare`: one table row per controller, figures embedded, opened in a real browser), and their bad input.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.studies.compare import contenders, lineup
from robotadapt.studies.scenarios import available, book_scenarios, load

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run")
FIGURES = ("tracking_error.png", "parameters.png", "torques.png")
# the lineup on Example 6.3.1: computed torque from its φ̂(0) = 0 has M̂ = 0 and is skipped (robotadapt.studies.compare)
APPLY = list(contenders("joint"))  # every law applies: the fixed-estimate baselines hold the nominal model


class Elements(HTMLParser):
    """The attributes of every element, by tag."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: dict[str, list[dict[str, str | None]]] = {}

    def handle_starttag(self, tag, attrs):
        self.tags.setdefault(tag, []).append(dict(attrs))


def elements(text: str) -> dict[str, list[dict[str, str | None]]]:
    parser = Elements()
    parser.feed(text)
    return parser.tags


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def comparison(tmp_path_factory) -> Path:
    """The default comparison on Example 6.3.1's two-link arm, 0.5 s."""
    out = tmp_path_factory.mktemp("compare")
    code, stdout, _ = cli("compare", "example-6.3.1", "--t-final", "0.5", "--out", str(out))
    assert code == 0, stdout
    return out


def test_gallery_lists_every_book_example_with_its_three_figures(tmp_path):
    code, stdout, _ = cli("figures", "--out", str(tmp_path), "--t-final", "0.05")
    assert code == 0
    names = [n for n in available() if n.startswith(("example-", "problem-"))]
    assert book_scenarios() == names and len(names) >= 20
    page = (tmp_path / "index.html").read_text(encoding="utf-8")
    sections = [s["data-scenario"] for s in elements(page)["section"]]
    assert sections == names
    images = {img["src"] for img in elements(page)["img"]}
    for name in names:
        for figure in FIGURES:
            assert (tmp_path / name / figure).stat().st_size > 5_000, (name, figure)
            assert f"{name}/{figure}" in images
        metrics = json.loads((tmp_path / name / "metrics.json").read_text())
        assert metrics["t_end"] < 0.051  # the last step may end past the cap (7.2.2: dt = 2π/4000)
        assert available()[name] in page or name in page
    assert page.count("capped with --t-final") == len(names)  # every scenario is longer than 0.05 s
    assert "Kv = 10" in page and "rms_error" in page  # settings and metrics are shown


def test_comparison_has_one_row_per_controller_and_embedded_figures(comparison):
    page = (comparison / "report.html").read_text(encoding="utf-8")
    tags = elements(page)
    rows = [tr["data-controller"] for tr in tags["tr"] if "data-controller" in tr]
    assert rows == APPLY  # every controller of chapters 6–7 but one applies to the two-link arm tracking sin t
    images = [img["src"] for img in tags["img"]]
    assert len(images) == 4 and all(src.startswith("data:image/png;base64,") for src in images)
    for src in images:
        pixels = matplotlib.image.imread(io.BytesIO(base64.b64decode(src.split(",", 1)[1])), format="png")
        assert pixels.shape[0] > 300 and pixels.shape[1] > 600
    assert "src=\"http" not in page and "<link" not in page  # self-contained
    for name in ("errors", "parameter_errors", "torques", "laws"):  # the same figures as files, for documents to link
        assert (comparison / f"{name}.png").read_bytes() in {base64.b64decode(src.split(",", 1)[1]) for src in images}
    data = json.loads((comparison / "comparison.json").read_text())
    assert [r["controller"] for r in data["rows"]] == APPLY
    assert not data["skipped"]
    for row in data["rows"]:
        assert row["status"] == "ok"
        assert row["us_per_step"] > 0 and row["peak_torque"] > 0 and row["rms_error_norm"] > 0
        assert "rms_error" not in row  # the per-joint metric of metrics.json: the table has the one scalar
    by_name = {r["controller"]: r for r in data["rows"]}
    assert by_name["repetitive"]["final_phi_error"] is None  # learns a signal, not φ
    assert "round(T/dt) = 6283" in by_name["repetitive"]["note"]  # dt = 1e-3 does not divide 2π: the nearest delay


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary: install Debian's `chromium` package "
                    "(apt-get install -y chromium) to render the report in a real browser")
def test_comparison_report_renders_in_headless_chromium(comparison):
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, "--dump-dom", (comparison / "report.html").as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    tags = elements(dom)
    assert [tr["data-controller"] for tr in tags["tr"] if "data-controller" in tr] == APPLY
    assert len([img for img in tags["img"] if img["src"].startswith("data:image/png;base64,")]) == 4
    assert re.search(r"<table id=\"comparison\">.*?</table>", dom, re.S)


def test_the_scenarios_own_controller_takes_its_place_in_the_lineup():
    """Example 6.5.2(a) runs Slotine–Li with λ = 5: the slotine_li entry uses it; a controller that matches no entry
    (a passivity law with the PD servo and the gradient law) joins as "scenario"."""
    entries, _ = lineup(load("example-6.5.2a"), ["slotine_li"])
    assert entries[0].scenario.data["controller"]["Lam"] == 5.0 and "gains: the scenario" in entries[0].source
    own = load("problem-6.4-1", ["controller.servo={kind = 'pd', Lam = 2.5}"])
    entries, skipped = lineup(own)
    assert entries[-1].name == "scenario" and entries[-1].reference
    assert not skipped and len(entries) == len(contenders("joint")) + 1  # the baselines hold the true φ: M̂ = M


def test_comparison_on_a_non_periodic_trajectory_skips_the_repetitive_law(tmp_path):
    code, stdout, _ = cli("compare", "example-6.5.1", "--t-final", "0.2", "--controllers", "slotine_li,pd",
                          "--out", str(tmp_path))
    assert code == 0 and "Slotine–Li" in stdout
    entries, skipped = lineup(load("example-6.5.1"))
    assert "repetitive" in skipped and "periodic" in skipped["repetitive"]
    assert set(skipped) == {"repetitive"} and len(entries) == len(contenders("joint")) - 1


@pytest.mark.parametrize(("argv", "field"), [
    (["compare", "example-6.3.1", "--controllers", "slotine_li,nonesuch"], "--controllers: unknown controller"),
    (["compare", "example-6.3.1", "--controllers", "slotine_li,,pd"], "--controllers"),
    (["compare", "example-6.5.1", "--controllers", "repetitive"], "--controllers: repetitive does not apply"),
    (["compare", "example-6.3.10"], "scenario: unknown scenario"),
    (["figures", "--t-final", "-1"], "--t-final: must be positive"),
])
def test_bad_input_exits_2_with_one_line(tmp_path, argv, field):
    code, _, err = cli(*argv, "--out", str(tmp_path / "out"))
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"robotadapt: error: {field}"), err


@pytest.mark.slow
def test_default_comparison_on_the_two_link_arm_answers_the_books_open_question(tmp_path):
    """Example 6.3.1's setting, 10 s: the adaptive laws with convergent estimates drive e to zero; the fixed-estimate
    law and PD keep a bounded error that does not decay (Example 6.2.1); every run is stable."""
    code, _, _ = cli("compare", "example-6.3.1", "--out", str(tmp_path))
    rows = {r["controller"]: r for r in json.loads((tmp_path / "comparison.json").read_text())["rows"]}
    assert code == 0 and all(r["status"] == "ok" for r in rows.values())
    for name in ("slotine_li", "sigma", "dcal", "adaptive_computed_torque", "passivity_pi", "sign_robust"):
        assert rows[name]["final_error"] < 1e-4 and rows[name]["convergence_time"] is not None, name
    for name in ("pd", "pd_gravity"):
        assert rows[name]["final_error"] > 1e-2 and rows[name]["convergence_time"] is None, name
    assert rows["slotine_li"]["final_phi_error"] < 1e-6


@pytest.fixture(scope="module")
def fair_comparison(tmp_path_factory) -> Path:
    """`compare --fair` on Example 6.3.1's arm, 0.5 s: Slotine–Li and the switching law sign_robust (tuned through its
    surrogate)."""
    out = tmp_path_factory.mktemp("fair")
    code, stdout, _ = cli("compare", "example-6.3.1", "--t-final", "0.5", "--backend", "jax", "--fair",
                          "--max-torque", "150", "--tune-runs", "4", "--controllers", "slotine_li,sign_robust",
                          "--out", str(out))
    assert code == 0, stdout
    return out


def test_fair_comparison_tunes_each_law_under_the_budget(fair_comparison):
    data = json.loads((fair_comparison / "comparison.json").read_text())
    assert data["fair"] == {"objective": "rms_error", "max_torque": 150.0}
    rows = {r["controller"]: r for r in data["rows"]}
    assert set(rows["slotine_li"]["tuned_gains"]) == {"controller.Lam", "controller.Kv", "controller.Gamma"}
    assert set(rows["sign_robust"]["tuned_gains"]) == {"controller.base.Lam", "controller.base.Kv",
                                                        "controller.base.Gamma"}
    for name, row in rows.items():  # the flag is the exact check of the row's own run, which its file reproduces
        assert row["within_budget"] == (row["peak_torque"] <= 150.0)
        assert row["scenario_file"] == f"tuned/{name}.toml"
        again = load(str(fair_comparison / row["scenario_file"])).run()
        assert np.sqrt(np.mean(np.sum(again.e**2, axis=1))) == pytest.approx(row["objective"], rel=1e-9, abs=0)
        assert np.max(np.abs(again.tau)) == pytest.approx(row["peak_torque"], rel=1e-9)
    page = (fair_comparison / "report.html").read_text(encoding="utf-8")
    assert "Fair comparison" in page and "150" in page


def test_fair_needs_a_budget(tmp_path):
    code, _, err = cli("compare", "example-6.3.1", "--fair", "--out", str(tmp_path))
    assert code == 2 and err.startswith("robotadapt: error: --max-torque")


@pytest.mark.parametrize("args, says", [(["--workers", "2"], "--workers: applies to --fair (the laws tuned at once)"),
                                        (["--fair", "--max-torque", "100", "--workers", "0"],
                                         "--workers: must be at least 1, got 0")])
def test_workers_are_the_fair_comparisons_and_at_least_one(tmp_path, args, says):
    code, _, err = cli("compare", "example-6.3.1", *args, "--out", str(tmp_path))
    assert code == 2 and err.strip() == f"robotadapt: error: {says}" and not any(tmp_path.iterdir())


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary: install Debian's `chromium` package "
                    "(apt-get install -y chromium) to render the report in a real browser")
def test_fair_report_renders_in_headless_chromium(fair_comparison):
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, "--dump-dom", (fair_comparison / "report.html").as_uri()],
                         capture_output=True, text=True, timeout=120).stdout
    tags = elements(dom)
    assert [tr["data-controller"] for tr in tags["tr"] if "data-controller" in tr] == ["slotine_li", "sign_robust"]
    assert "Fair comparison" in dom
