"""How a figure is written: its file format and resolution (`--format`, `--dpi`), and :func:`save_figure`, the one
place a matplotlib figure becomes a file (atomically, then closed).

Imports no matplotlib at module level: the command line reads :data:`FORMATS` and :data:`DEFAULT_DPI` to build its
parsers, and the figure modules that call :func:`save_figure` have loaded matplotlib already.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..files import atomic_write
from ..validation import ConfigError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: the file formats a figure can be written in: png (raster), pdf and svg (vector, for papers)
FORMATS = ("png", "pdf", "svg")
#: dots per inch unless asked: sharp on a high-density screen and in print at column width (use 300 or more for a
#: raster figure in a paper); pdf and svg are vector graphics, in which the dpi sets only the rasterised parts
DEFAULT_DPI = 150


@dataclass(frozen=True)
class FigureFormat:
    """A figure's file format (one of :data:`FORMATS`) and resolution in dots per inch; bad values are a ConfigError
    naming `--format` or `--dpi`."""

    format: str = "png"
    dpi: int = DEFAULT_DPI

    def __post_init__(self) -> None:
        if self.format not in FORMATS:
            raise ConfigError("--format", f"expected one of {', '.join(FORMATS)}, got {self.format!r}")
        if isinstance(self.dpi, bool) or not isinstance(self.dpi, int) or self.dpi < 1:
            raise ConfigError("--dpi", f"expected a positive whole number of dots per inch, got {self.dpi!r}")

    @property
    def suffix(self) -> str:
        """The file suffix, e.g. ".pdf"."""
        return f".{self.format}"

    def name(self, stem: str) -> str:
        """The file name of the figure `stem`: "torques" → "torques.pdf"."""
        return stem + self.suffix


#: the default: png at `DEFAULT_DPI`
PNG = FigureFormat()


def render(fig: Figure, output: FigureFormat = PNG) -> bytes:
    """`fig` in `output`'s format and dpi, as bytes; the figure stays open."""
    buf = io.BytesIO()
    fig.savefig(buf, format=output.format, dpi=output.dpi)
    return buf.getvalue()


def save_figure(fig: Figure, path: Path, output: FigureFormat = PNG) -> Path:
    """Write `fig` to `path` (name it with `output.suffix`) in `output`'s format and dpi, whole or not at all, and
    close the figure, also when drawing fails; returns `path`."""
    import matplotlib.pyplot as plt

    try:
        atomic_write(path, lambda f: f.write(render(fig, output)), binary=True)
    finally:
        plt.close(fig)
    return path
