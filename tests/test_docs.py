"""The documentation: generated pages are current, the tutorial's code runs, the site builds with no warning."""

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _generator():
    spec = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


DOCTESTED = ["robotadapt", "robotadapt.sim.batch", "robotadapt.sim.simulation"]


def test_every_module_with_docstring_examples_is_listed():
    src = ROOT / "src"
    found = sorted(".".join(p.relative_to(src).with_suffix("").parts).removesuffix(".__init__")
                   for p in (src / "robotadapt").rglob("*.py") if ">>>" in p.read_text(encoding="utf-8"))
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


MKDOCS = Path(sys.executable).parent / "mkdocs"
needs_mkdocs = pytest.mark.skipif(not MKDOCS.exists(), reason="mkdocs not installed: pip install -e '.[dev]'")
CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
# the flags this machine needs (as tests/test_report.py), and no network: every host name fails to resolve and any
# other connection goes to a dead proxy, so MathJax must come from the site itself
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run",
                  "--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=127.0.0.1:9", "--virtual-time-budget=30000")


def build_site(config: Path, site: Path) -> subprocess.CompletedProcess:
    """`mkdocs build --strict` at its default verbosity (warnings are printed), as `make docs` runs it."""
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}  # Material's end-of-life banner, not a problem of these docs
    return subprocess.run([str(MKDOCS), "build", "--strict", "-f", str(config), "-d", str(site)], cwd=config.parent,
                          capture_output=True, text=True, timeout=300, env=env)


def assert_clean(run: subprocess.CompletedProcess) -> None:
    output = run.stdout + run.stderr
    assert run.returncode == 0, output
    assert "WARNING" not in output, output


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built once from the repository's docs."""
    if not MKDOCS.exists():
        pytest.skip("mkdocs not installed: pip install -e '.[dev]'")
    out = tmp_path_factory.mktemp("site")
    run = build_site(ROOT / "mkdocs.yml", out)
    assert_clean(run)
    return out


@needs_mkdocs
def test_site_builds_with_no_warning(site):
    assert (site / "tutorial.html").exists()  # use_directory_urls: false, so that the site works opened from disk
    assert (site / "laws.html").exists()
    assert (site / "javascripts" / "mathjax" / "tex-svg.js").stat().st_size > 100_000  # served by the site itself


@needs_mkdocs
def test_the_check_fails_on_a_planted_warning(tmp_path):
    """A copy of the docs with one broken link: the build must fail the check that the real docs pass."""
    shutil.copytree(DOCS, tmp_path / "docs", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "mkdocs.yml", tmp_path / "mkdocs.yml")
    (tmp_path / "src").symlink_to(ROOT / "src")  # mkdocstrings' `paths: [src]` is relative to the config
    page = tmp_path / "docs" / "laws.md"
    page.write_text(page.read_text(encoding="utf-8") + "\nSee [a page that does not exist](no-such-page.md).\n",
                    encoding="utf-8")
    run = build_site(tmp_path / "mkdocs.yml", tmp_path / "site")
    with pytest.raises(AssertionError, match="no-such-page"):
        assert_clean(run)


def test_laws_page_cites_every_law_next_to_its_code():
    text = (DOCS / "laws.md").read_text(encoding="utf-8")
    for anchor, table, code in [
            ("adaptive-computed-torque", "6.2.19", "robotadapt.controllers.computed_torque.AdaptiveComputedTorque"),
            ("slotine-li", "6.3.14", "robotadapt.controllers.inertia_related.InertiaRelated"),
            ("passivity", "6.4.4", "robotadapt.controllers.passivity.PassivityBased"),
            ("gradient", "Example 6.4.1", "robotadapt.controllers.adaptation.Gradient"),
            ("landau-pi", "6.4.21", "robotadapt.controllers.adaptation.LandauPI"),
            ("sigma-modification", "6.7.14", "robotadapt.controllers.adaptation.SwitchingSigma"),
            ("composite", "6.6.28", "robotadapt.controllers.composite.Composite"),
            ("sign-robust", "6.7.8", "robotadapt.controllers.robust.SignRobust"),
            ("dcal", "7.2.26", "robotadapt.controllers.dcal.DCAL"),
            ("repetitive", "7.2.48", "robotadapt.controllers.repetitive.Repetitive"),
            ("baselines", "6.2.2", "robotadapt.controllers.baseline.ComputedTorque")]:
        heading = text.rindex("\n", 0, text.index(f"{{#{anchor}}}")) + 1  # the section: its heading to the next `## `
        section = text[heading:].split("\n## ", 1)[0]
        assert table in section and f"`{code}`" in section, anchor
    assert "spec §" not in text


def test_no_user_facing_text_cites_the_spec_file():
    """The spec is not in the repository: scenario notes (shown by `robotadapt list` and the reports) cite the docs."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    anchors = set(re.findall(r"\{#([\w-]+)\}|<a id=\"([\w-]+)\">", (DOCS / "laws.md").read_text(encoding="utf-8")))
    anchors = {a or b for a, b in anchors}
    for path in sorted((ROOT / "src" / "robotadapt" / "studies" / "scenarios").glob("*.toml")):
        name, data = path.stem, tomllib.loads(path.read_text(encoding="utf-8"))
        text = str(data.get("description", "")) + " " + str(data.get("notes", ""))
        assert "spec §" not in text and "spec/" not in text, name
        for anchor in re.findall(r"laws\.md#([\w-]+)", text):
            assert anchor in anchors, (name, anchor)


@needs_mkdocs
@pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary: install Debian's `chromium` package "
                    "(apt-get install -y chromium) to render the docs' mathematics in a real browser")
def test_laws_page_renders_its_mathematics_offline_in_headless_chromium(site):
    page = site / "laws.html"
    source = page.read_text(encoding="utf-8")
    assert "://" not in "".join(re.findall(r"<script[^>]*src=\"([^\"]*)\"", source))  # every script is local
    expected = len(re.findall(r'class="arithmatex"', source))
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, "--dump-dom", page.as_uri()],
                         capture_output=True, text=True, timeout=180).stdout
    assert expected > 100
    assert dom.count("<mjx-container") == expected  # every formula typeset by MathJax
    assert dom.count('data-mml-node="mlabeledtr"') == source.count("\\tag{") > 30  # equation numbers (6.3.14)…
    assert '<g data-mml-node="merror"' not in dom  # no TeX error
