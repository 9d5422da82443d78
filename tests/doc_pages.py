"""Running a documentation page's code blocks as a reader would: in an empty folder, in order, in fresh processes."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

FENCE = re.compile(r"^```(\w+)\n(.*?)^```$", re.S | re.M)
FILE = re.compile(r"^(?:# |<!-- )file: ([^\s>]+)(?: -->)?\n")


def blocks(page: Path) -> list[tuple[str, str]]:
    """The page's fenced code blocks as (language, code), in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(page.read_text(encoding="utf-8"))]


def run_page(page: Path, folder: Path, timeout: float = 600.0, python: Path | None = None) -> str:
    """Run `page`'s blocks in `folder`: a block starting `# file: NAME` (or `<!-- file: NAME -->`) is saved as NAME,
    the other python blocks run as one script (`python page.py`, as a reader pasting them into one session), then each
    line of a `sh` block, with the environment's `robotadapt` on the PATH (`python`: another environment's
    interpreter, its folder then on the PATH). Returns everything printed; a failing block fails with its output."""
    python = python or Path(sys.executable)
    bin_dir = str(python.parent)
    env = {**os.environ, "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""), "MPLBACKEND": "Agg"}
    script, commands = [], []
    for lang, code in blocks(page):
        saved = FILE.match(code)
        if saved:
            (folder / saved.group(1)).write_text(code, encoding="utf-8")
        elif lang == "python":
            script.append(code)
        elif lang == "sh":
            commands += [line.split("#")[0].strip() for line in code.splitlines() if line.split("#")[0].strip()]
    (folder / "page.py").write_text("\n".join(script), encoding="utf-8")
    out = []
    for argv in ([str(python), "page.py"], *[["sh", "-c", c] for c in commands]):
        done = subprocess.run(argv, cwd=folder, env=env, capture_output=True, text=True, timeout=timeout)
        out.append(done.stdout)
        assert done.returncode == 0, f"{' '.join(argv)} failed ({done.returncode}):\n{done.stdout}\n{done.stderr}"
    return "".join(out)
