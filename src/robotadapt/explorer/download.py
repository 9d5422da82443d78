"""A run's files as one zip: scenario.toml (what `robotadapt run` reproduces), result.npz and metrics.json, written as
`robotadapt run` writes them."""

from __future__ import annotations

import io
import re
import tempfile
import zipfile
from pathlib import Path

from ..report.files import save_result
from .catalogue import Run

FILES = ("scenario.toml", "result.npz", "metrics.json")


def filename(run: Run) -> str:
    """The zip's name: the scenario's, `example-6.3.1 [pd]` as `example-6.3.1-pd.zip`."""
    return re.sub(r"[^\w.]+", "-", run.scenario.name).strip("-") + ".zip"


def archive(run: Run) -> bytes:
    """The zip of :data:`FILES` for `run`."""
    with tempfile.TemporaryDirectory(prefix="robotadapt-explore-") as folder:
        save_result(run.result, folder, run.scenario.text, model=run.model)
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
            for name in FILES:
                z.write(Path(folder) / name, name)
    return out.getvalue()
