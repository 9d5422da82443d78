"""How a figure is made and written: :func:`new_figure`, the one place a figure of the package is created (a
matplotlib `Figure` on its own Agg canvas, never through pyplot), its file format and resolution (`--format`,
`--dpi`), and :func:`save_figure`, the one place a matplotlib figure becomes a file (atomically, then closed).

Neither pyplot nor a backend switch: drawing a figure leaves the user's matplotlib as it was (a notebook's backend, its
open figures). Imports no matplotlib at module level: the command line reads :data:`FORMATS` and :data:`DEFAULT_DPI` to
build its parsers, and the figure modules that call :func:`save_figure` have loaded matplotlib already.
"""

from __future__ import annotations

import io
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

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


def new_figure(**kwargs: Any) -> Figure:
    """A matplotlib `Figure(**kwargs)` (figsize, dpi, layout, ...) drawn on its own Agg canvas, as pyplot under the
    Agg backend would give, without pyplot: no backend chosen, no figure registered in pyplot's state. Lay it out with
    `fig.subplots`, write it with :func:`save_figure` or :func:`render` (pdf and svg switch to their own canvas)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)  # attaches itself: layout and drawing to a buffer use the Agg renderer at the figure's dpi
    return fig


def render(fig: Figure, output: FigureFormat = PNG) -> bytes:
    """`fig` in `output`'s format and dpi, as bytes; the figure stays open."""
    buf = io.BytesIO()
    fig.savefig(buf, format=output.format, dpi=output.dpi)
    return buf.getvalue()


def save_figure(fig: Figure, path: Path, output: FigureFormat = PNG) -> Path:
    """Write `fig` to `path` (name it with `output.suffix`) in `output`'s format and dpi, whole or not at all, and
    close the figure, also when drawing fails; returns `path`. A figure of :func:`new_figure` has nothing to close; one
    a caller made with pyplot is closed in pyplot (which is not imported here when the caller has not)."""
    try:
        atomic_write(path, lambda f: f.write(render(fig, output)), binary=True)
    finally:
        pyplot = sys.modules.get("matplotlib.pyplot")
        if pyplot is not None:
            pyplot.close(fig)
    return path
