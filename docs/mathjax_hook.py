"""MkDocs hook: serve MathJax from the site itself, so the mathematics renders with no network.

The script is `tex-svg.js` of MathJax 3 (SVG output: glyphs are paths, no web fonts to fetch), taken from the
`django-static-mathjax` package of the `dev` extra (a pip package that ships MathJax's built files and nothing else
in use here) and added to the site as `javascripts/mathjax/tex-svg.js`; mkdocs.yml loads it after
docs/javascripts/mathjax-config.js.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

SITE_PATH = "javascripts/mathjax/tex-svg.js"


def mathjax_script() -> Path:
    """The packaged MathJax 3 single-file SVG build; a clear error when the `dev` extra is not installed."""
    try:
        import mathjax
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError("MathJax for the docs comes from the django-static-mathjax package: "
                           "pip install -e '.[dev]'") from exc
    path = Path(mathjax.__file__).parent / "static" / "mathjax" / "es5" / "tex-svg.js"
    if not path.is_file():  # pragma: no cover
        raise RuntimeError(f"django-static-mathjax has no {path}")
    return path


def on_files(files: Files, config) -> Files:
    files.append(File.generated(config, SITE_PATH, abs_src_path=str(mathjax_script())))
    return files
