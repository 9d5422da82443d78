"""The built documentation site as a newcomer reads it: headings in the API reference, mathematics with no stray `$`,
links that work opened from disk, a grouped nav, code lines that fit the page, and a front page that tells the truth.

The site is built once for this module (`build_site` of tests/test_docs.py, warnings are errors); the browser test
skips, saying why, where there is no Chromium."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest
import yaml

from test_docs import CHROMIUM, CHROMIUM_FLAGS, DOCS, MKDOCS, ROOT, assert_clean, build_site

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="no chromium binary: install Debian's `chromium` package "
                                    "(apt-get install -y chromium) to measure the docs' layout in a real browser")

EXCLUDED = {"generate.py", "mathjax_hook.py"}  # mkdocs.yml's exclude_docs


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    """The site built once from the repository's docs, with no warning."""
    if not MKDOCS.exists():
        pytest.skip("mkdocs not installed: pip install -e '.[dev]'")
    out = tmp_path_factory.mktemp("site")
    assert_clean(build_site(ROOT / "mkdocs.yml", out))
    return out


# --- a small HTML tree (the standard library's parser; no third-party HTML package in the dev extra) -----------------

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "param", "source", "track", "wbr"}


class Node:
    def __init__(self, tag: str, attrs: dict[str, str], parent: Node | None):
        self.tag, self.attrs, self.parent, self.children = tag, attrs, parent, []

    @property
    def classes(self) -> set[str]:
        return set(self.attrs.get("class", "").split())

    def iter(self):
        for child in self.children:
            if isinstance(child, Node):
                yield child
                yield from child.iter()

    def find_all(self, tag: str | None = None, cls: str | None = None, **attrs: str) -> list[Node]:
        return [n for n in self.iter() if (tag is None or n.tag == tag) and (cls is None or cls in n.classes)
                and all(n.attrs.get(k) == v for k, v in attrs.items())]

    def text(self) -> str:
        return "".join(c if isinstance(c, str) else c.text() for c in self.children)

    def ancestors(self):
        node = self.parent
        while node is not None:
            yield node
            node = node.parent


class _TreeBuilder(HTMLParser):
    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.root = self.node = Node("#document", {}, None)

    def handle_starttag(self, tag, attrs):
        node = Node(tag, {k: v or "" for k, v in attrs}, self.node)
        self.node.children.append(node)
        if tag not in VOID:
            self.node = node

    def handle_endtag(self, tag):
        for open_node in [self.node, *self.node.ancestors()]:  # close up to the matching open element, if any
            if open_node.tag == tag:
                self.node = open_node.parent or self.root
                return

    def handle_data(self, data):
        self.node.children.append(data)


def parse(path: Path) -> Node:
    builder = _TreeBuilder()
    builder.feed(path.read_text(encoding="utf-8"))
    return builder.root


def heading_text(heading: Node) -> str:
    """A heading's words, without its permalink (¶)."""
    return " ".join("".join(c if isinstance(c, str) else ("" if "headerlink" in c.classes else c.text())
                            for c in heading.children).split())


# --- 1. the API reference: a heading per class and module, members under their class ----------------------------------

def api_directives() -> list[str]:
    return re.findall(r"^::: (robotadapt\.[\w.]+)\s*$", (DOCS / "api.md").read_text(encoding="utf-8"), re.M)


def is_class_path(path: str) -> bool:
    return path.rsplit(".", 1)[1][:1].isupper()


@pytest.fixture(scope="module")
def api(built) -> Node:
    return parse(built / "api.html")


def test_api_reference_documents_classes_and_modules():
    directives = api_directives()
    assert len(directives) > 30
    assert {"robotadapt.robots.base.RobotModel", "robotadapt.robots.two_link.TwoLinkArm"} <= set(directives)
    assert any(not is_class_path(p) for p in directives)


@pytest.mark.parametrize("path", api_directives())
def test_every_api_reference_object_has_a_heading_with_its_name(api, path):
    """Each `::: path` of docs/api.md is an h3 (under the page's `##` sections): a class by its name with the class
    badge, a module by its full dotted path with the module badge."""
    found = api.find_all(id=path)
    assert len(found) == 1 and found[0].tag == "h3" and "doc-heading" in found[0].classes, (path, found)
    heading = found[0]
    kind = "class" if is_class_path(path) else "module"
    words = heading_text(heading).split()
    assert words and words[0] == (path.rsplit(".", 1)[1] if kind == "class" else path), (path, words)
    assert heading.find_all("code", cls=f"doc-symbol-{kind}"), f"{path}: no {kind} badge in its heading"


def test_every_class_opens_with_its_heading_not_with_its_bases(api):
    """The trial found members under "Bases: ABC" with no class name above them."""
    classes = api.find_all("div", cls="doc-class")
    assert len(classes) > 50
    for div in classes:
        first = next(c for c in div.children if isinstance(c, Node))
        assert first.tag in {"h3", "h4", "h5", "h6"} and "doc-heading" in first.classes, div.attrs
    for bases in api.find_all("p", cls="doc-class-bases"):
        holder = next(a for a in bases.ancestors() if "doc-class" in a.classes)
        assert any(isinstance(c, Node) and "doc-heading" in c.classes for c in holder.children)


@pytest.mark.parametrize("cls", ["robotadapt.robots.base.RobotModel", "robotadapt.robots.two_link.TwoLinkArm"])
def test_a_method_sits_under_its_class_in_the_page_and_in_the_table_of_contents(api, cls):
    """`TwoLinkArm.regressor` and `RobotModel.regressor` are told apart: each inside its class's block, a level below
    the class's heading, and nested under the class's entry in the table of contents."""
    method = f"{cls}.regressor"
    (heading,) = api.find_all(id=cls)
    (member,) = api.find_all(id=method)
    block = heading.parent
    assert "doc-class" in block.classes and block in list(member.ancestors())
    assert int(member.tag[1]) == int(heading.tag[1]) + 1
    (sidebar,) = api.find_all("div", cls="md-sidebar--secondary")  # the table of contents at the right
    (toc,) = sidebar.find_all("nav", cls="md-nav--secondary")
    (entry,) = [a for a in toc.find_all("a") if a.attrs.get("href") == f"#{cls}"]
    item = entry.parent
    assert entry.text().split()[-1] == cls.rsplit(".", 1)[1]
    nested = [a.attrs.get("href") for sub in item.find_all("nav") for a in sub.find_all("a")]
    assert f"#{method}" in nested, nested
    other = [a for a in toc.find_all("a") if a.attrs.get("href") == f"#{method}"]
    assert len(other) == 1  # one entry for this class's regressor, the other class's has its own anchor


# --- 2. mathematics: no `$` left in the rendered text ------------------------------------------------------------------

SKIPPED_TEXT = {"code", "pre", "script", "style", "kbd", "samp", "textarea"}


def stray_dollars(page: Path) -> list[str]:
    """Text with a `$` outside code and outside the formulas that arithmatex marked for MathJax."""
    out = []

    def walk(node: Node) -> None:
        if node.tag in SKIPPED_TEXT or "arithmatex" in node.classes:
            return
        for child in node.children:
            if isinstance(child, str):
                if "$" in child:
                    out.append(" ".join(child.split())[:160])
            else:
                walk(child)

    (article,) = parse(page).find_all("article")
    walk(article)
    return out


def test_laws_page_has_no_stray_dollar_in_its_rendered_text(built):
    page = built / "laws.html"
    assert len(re.findall(r'class="arithmatex"', page.read_text(encoding="utf-8"))) > 100
    assert stray_dollars(page) == []


def test_laws_page_lists_the_four_facts_of_the_model_as_four_items(built):
    """The display equation inside the third fact is a block of its own item: the list around it stays whole."""
    tree = parse(built / "laws.html")
    (facts,) = [ol for ol in tree.find_all("ol") if "Bounded inertia." in ol.text()]
    items = [li for li in facts.children if isinstance(li, Node) and li.tag == "li"]
    assert [li.text().split(".")[0].strip() for li in items] == [
        "Bounded inertia", "Skew symmetry", "Linear in the parameters, in two slots", "Bounds"]
    assert items[2].find_all("div", cls="arithmatex")  # the equation Y(q, q̇, v, a) φ, displayed


def test_no_page_has_a_stray_dollar_in_its_rendered_text(built):
    """A `$$…$$` inside a paragraph, or an unmatched `$`, is left as text by arithmatex: seen on any page."""
    found = {p.name: stray_dollars(p) for p in sorted(built.glob("*.html")) if p.name != "404.html"}
    assert {name: text for name, text in found.items() if text} == {}


def test_the_planted_inline_display_equation_is_caught(tmp_path):
    """The check itself: the display equation the trial found, written inside a list item's paragraph."""
    page = tmp_path / "page.html"
    page.write_text('<article><ol><li>For any vectors,\n   $<span class="arithmatex">\\(Y\\phi\\)</span>$\n   which is '
                    '<code>$x</code></li></ol></article>', encoding="utf-8")
    assert stray_dollars(page) == ["For any vectors, $", "$ which is"]


# --- 3. links that work opened from disk ---------------------------------------------------------------------------

def local_links(page: Node) -> list[str]:
    links = [n.attrs["href"] for n in page.find_all("a") if "href" in n.attrs]
    return [h for h in links if not urlsplit(h).scheme and not h.startswith(("#", "//"))]


def test_config_asks_for_html_file_urls():
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    assert config["use_directory_urls"] is False


def test_every_nav_link_is_a_page_html_file_on_disk(built):
    """Opened as file://, a link to `tutorial/` shows a folder listing: every link of the nav (and the logo's) names
    an `.html` file that exists, relative to the page that links it."""
    pages = sorted(p for p in built.glob("*.html") if p.name != "404.html")  # 404 is served by a web server only
    assert {p.stem for p in pages} >= {"index", "tutorial", "laws", "api", "own-arm"}
    assert not any((built / p.stem / "index.html").exists() for p in pages if p.stem != "index")
    for page in pages:
        tree = parse(page)
        navs = [n for n in tree.find_all("nav", cls="md-nav--primary")] + tree.find_all("a", cls="md-logo")
        hrefs = [a.attrs["href"] for nav in navs for a in ([nav] if nav.tag == "a" else nav.find_all("a"))
                 if "href" in a.attrs and not a.attrs["href"].startswith("#")]
        assert len(hrefs) >= len(pages), page.name
        for href in hrefs:
            path = unquote(urlsplit(href).path)
            assert path.endswith(".html"), (page.name, href)
            assert (page.parent / path).resolve().is_file(), (page.name, href)


def test_every_local_link_of_every_page_resolves_to_a_file(built):
    """The links in the text too (mkdocs rewrites `page.md` links): none is a folder, `.` or `x/`."""
    for page in sorted(p for p in built.glob("*.html") if p.name != "404.html"):
        for href in local_links(parse(page)):
            path = unquote(urlsplit(href).path)
            if not path:  # `?query` or an empty href: stays on the page
                continue
            target = (page.parent / path).resolve()
            assert not path.endswith("/") and path != "." and target.is_file(), (page.name, href)


def test_no_markdown_page_links_a_directory_style_url():
    """Links between pages name the `.md` file (mkdocs turns them into `.html`), never `page/` or `../page/`."""
    pattern = re.compile(r"\]\(([^)\s]+)\)|href=\"([^\"]+)\"")
    for md in sorted(DOCS.glob("*.md")):
        for a, b in pattern.findall(md.read_text(encoding="utf-8")):
            url = a or b
            if urlsplit(url).scheme or url.startswith("#"):
                continue
            path = urlsplit(url).path
            assert not path.endswith("/") and path not in {".", ".."}, (md.name, url)


# --- 4. the nav in sections ---------------------------------------------------------------------------------------------

GROUPS = ["Getting started", "Guides", "Reference"]


def nav_config() -> list:
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))["nav"]


def test_nav_is_grouped_into_sections_and_lists_every_page():
    nav = nav_config()
    assert [next(iter(item)) for item in nav] == GROUPS
    files = []
    for item in nav:
        ((_, pages),) = item.items()
        assert isinstance(pages, list) and len(pages) >= 3
        for page in pages:
            ((title, path),) = page.items()
            assert isinstance(path, str) and title, page
            files.append(path)
    assert len(files) == len(set(files))
    on_disk = {p.name for p in DOCS.iterdir() if p.suffix == ".md"}
    assert set(files) == on_disk, "every page of docs/ in the nav, and nothing else"
    assert not EXCLUDED & set(files)
    first = dict(next(iter(nav[0].values()))[0])
    assert list(first.values()) == ["index.md"]  # Home first
    getting_started = [next(iter(p.values())) for p in nav[0]["Getting started"]]
    assert getting_started[:3] == ["index.md", "tutorial.md", "own-arm.md"]
    reference = [next(iter(p.values())) for p in nav[2]["Reference"]]
    assert {"laws.md", "api.md", "notation.md", "keys.md", "cli.md"} <= set(reference)


def test_built_nav_shows_the_sections(built):
    tree = parse(built / "index.html")
    (primary,) = tree.find_all("nav", cls="md-nav--primary")
    sections = [li for li in primary.find_all("li", cls="md-nav__item--section")]
    titles = [" ".join(next(n for n in li.children if isinstance(n, Node) and n.tag == "label").text().split())
              for li in sections]
    assert titles == GROUPS
    links = {a.attrs["href"] for li in sections for a in li.find_all("a")}
    assert {"index.html", "tutorial.html", "own-arm.html", "laws.html", "api.html"} <= links


# --- 5. a 125-character code line fits at a laptop width -------------------------------------------------------------

LINE = 125  # ruff's line-length, and the widest code lines of the pages
WINDOW = (1440, 900)
MEASURE = """<script>
window.addEventListener('load', function () {
  var article = document.querySelector('article.md-content__inner');
  var pre = document.createElement('pre'), code = document.createElement('code');
  pre.id = 'probe'; code.textContent = 'x'.repeat(LINE) + '\\n' + 'y'.repeat(40); pre.appendChild(code);
  article.appendChild(pre);
  var blocks = [];
  article.querySelectorAll('pre > code').forEach(function (c) {
    var longest = Math.max.apply(null, c.textContent.split('\\n').map(function (l) { return l.length; }));
    blocks.push({id: c.parentNode.id, longest: longest, scroll: c.scrollWidth, client: c.clientWidth,
                 font: parseFloat(getComputedStyle(c).fontSize)});
  });
  var out = document.createElement('div');
  out.id = 'measured';
  out.textContent = JSON.stringify({inner: window.innerWidth, blocks: blocks});
  document.body.appendChild(out);
});
</script>""".replace("LINE", str(LINE))


def measure(site: Path, page: str, window: tuple[int, int]) -> dict:
    """Load a copy of `page` with a script that adds a code block of a 125-character line and writes, into the DOM,
    each code block's scrollWidth and clientWidth; Chromium at `window` dumps the DOM."""
    source = (site / page).read_text(encoding="utf-8")
    probe = site / f"_measure-{page}"
    probe.write_text(source.replace("</body>", MEASURE + "</body>"), encoding="utf-8")
    dom = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--window-size={window[0]},{window[1]}", "--dump-dom",
                          probe.as_uri()], capture_output=True, text=True, timeout=180).stdout
    found = re.search(r'<div id="measured">(.*?)</div>', dom, re.S)
    assert found, dom[-2000:]
    return json.loads(html.unescape(found.group(1)))


@pytest.fixture(scope="module")
def site_copy(built, tmp_path_factory) -> Path:
    """A copy of the site for the measuring pages, so that the other tests see the site as built."""
    copy = tmp_path_factory.mktemp("measured") / "site"
    shutil.copytree(built, copy)
    return copy


@needs_chromium
@pytest.mark.parametrize("page", ["results.html", "realtime.html", "api.html"])
def test_a_125_character_code_line_fits_at_1440_pixels_in_headless_chromium(site_copy, page):
    """The theme's 61rem grid left about 690 px between the sidebars at 1440 px, and a 125-character line (about
    1055 px at its 13.6 px) scrolled; docs/stylesheets/extra.css widens the grid and sets code at 12 px."""
    result = measure(site_copy, page, WINDOW)
    assert result["inner"] == WINDOW[0]
    blocks = result["blocks"]
    (probe,) = [b for b in blocks if b["id"] == "probe"]
    assert probe["longest"] == LINE
    assert probe["font"] >= 12, "readable: not fitted by shrinking the code below 12 px"
    assert probe["scroll"] <= probe["client"], probe  # no horizontal scroll
    assert len(blocks) > 1
    for block in blocks:
        if block["longest"] <= LINE:
            assert block["scroll"] <= block["client"], (page, block)


def test_the_extra_stylesheet_is_in_the_site(built):
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    assert "stylesheets/extra.css" in config["extra_css"]
    assert (built / "stylesheets" / "extra.css").is_file()
    assert 'href="stylesheets/extra.css"' in (built / "laws.html").read_text(encoding="utf-8")


# --- 6. the front page's claims ---------------------------------------------------------------------------------------

INDEX = DOCS / "index.md"


def requirement_name(spec: str) -> str:
    return re.split(r"[\s<>=!~;\[(]", spec.strip(), maxsplit=1)[0].lower().replace("_", "-")


def pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]


def makefile_recipe(target: str) -> str:
    """The lines of a Makefile target's recipe."""
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    found = re.search(rf"^{re.escape(target)}:[^\n]*\n((?:\t[^\n]*\n?)*)", text, re.M)
    assert found, target
    return found.group(1)


def test_index_names_the_core_dependencies_of_pyproject():
    text = INDEX.read_text(encoding="utf-8")
    paragraph = text[text.index("The core dependencies"):].split("\n\n", 1)[0]
    named = {n.lower().replace("_", "-") for n in re.findall(r"`([\w.-]+)`", paragraph)} - {"dependencies",
                                                                                         "pyproject.toml"}
    assert named == {requirement_name(d) for d in pyproject()["dependencies"]}
    assert "tomli` on Python 3.10" in paragraph  # its marker, python_version < '3.11', with requires-python >= 3.10
    assert any(requirement_name(d) == "tomli" and "python_version < '3.11'" in d for d in pyproject()["dependencies"])


def test_index_extras_table_installs_what_pyproject_says():
    rows = [line for line in INDEX.read_text(encoding="utf-8").splitlines() if line.startswith("| `[")]
    extras = pyproject()["optional-dependencies"]
    table = {}
    for row in rows:
        extra, installs, _ = (cell.strip() for cell in row.strip("|").split("|"))
        names = re.sub(r"\([^)]*\)", "", installs)
        table[extra.strip("`[]")] = set() if names.strip() == "nothing more" else {
            n.strip().lower() for n in names.split(",")}
    assert table == {name: {requirement_name(d) for d in deps} for name, deps in extras.items()}


def test_index_says_which_extras_make_test_installs():
    text = INDEX.read_text(encoding="utf-8")
    (claimed,) = re.findall(r"`make test` installs `\[([\w,]+)\]`", text)
    (installed,) = re.findall(r'install --quiet -e "\.\[([\w,]+)\]"', makefile_recipe("$(VENV)/.dev"))
    assert claimed == installed


def test_index_says_what_make_test_and_make_docs_run():
    """`make test` runs ruff, mypy and pytest -m "not slow" (the docs are built by tests/test_docs.py, into a temporary
    folder); `make docs` is the target that builds the site."""
    text = INDEX.read_text(encoding="utf-8")
    block = re.search(r"```sh\n(.*?)```", text, re.S).group(1)
    said = dict(re.findall(r"^make (\w+)\s+# (.*)$", block, re.M))
    assert set(said) == {"demo", "test", "docs"}
    test_recipe, docs_recipe = makefile_recipe("test"), makefile_recipe("docs")
    assert "ruff check" in test_recipe and "$(BIN)/mypy" in test_recipe and '-m "not slow"' in test_recipe
    assert "mkdocs" not in test_recipe and "docs build" not in said["test"]
    assert all(word in said["test"] for word in ("ruff", "mypy", '"not slow"'))
    assert "mkdocs build --strict" in docs_recipe and "mkdocs build --strict" in said["docs"]
    assert "robotadapt run example-6.3.1 --out results/example-6.3.1" in makefile_recipe("demo")
    assert "results/example-6.3.1/" in said["demo"]
    development = text[text.index("## Development"):]
    assert "`make docs` is what writes it to `site/`" in development
    assert "tests/test_docs.py" in development and (ROOT / "tests" / "test_docs.py").is_file()
    assert (ROOT / ".ci" / "run").is_file() and "make test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_index_says_make_test_installs_system_packages():
    text = INDEX.read_text(encoding="utf-8")
    recipe = makefile_recipe("system-packages")
    for package in ("chromium", "libosmesa6"):
        assert f"apt-get install -y -qq {package}" in " ".join(recipe.replace("\\\n", " ").split())
        assert f"`{package}`" in text
    assert "SYSTEM_PACKAGES=0" in text and 'SYSTEM_PACKAGES)" = 0' in recipe


def test_index_ten_lines_print_what_the_page_says():
    text = INDEX.read_text(encoding="utf-8")
    code = re.search(r"## Ten lines\n\n```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) <= 10
    expected = re.search(r"print\(.*\)\s+# (.*)$", code, re.M).group(1)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert " ".join(run.stdout.split()) == expected
