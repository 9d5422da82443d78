"""Drawing leaves the user's matplotlib alone (issue 41): every figure of the package is a `matplotlib.figure.Figure`
made without pyplot, so `ra.save_figures`, the comparison report, a sweep's and a study's figures neither switch the
backend the user chose (a notebook's) nor import pyplot, nor close or add to the user's pyplot figures.

Each check runs in a fresh interpreter: the backend of this test process, and its pyplot, do not matter.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: what a user does first: a backend that is not Agg and works without a display
USER = """
import sys
from pathlib import Path

import matplotlib

matplotlib.use("svg")
out = Path(sys.argv[1])
"""

#: the figures: a run through the front door, then what the command line draws (comparison report, sweep, study, PE)
DRAW = """
import robotadapt as ra

scenario = ra.load("example-6.3.1", ["simulation.t_final=0.2"])
res = scenario.run()
written = ra.save_figures(res, out / "run", "example-6.3.1", scenario.setup.controller.model)
assert [p.name for p in written] == ["tracking_error.png", "parameters.png", "torques.png"], written
svg = ra.save_figures(res, out / "svg", output=ra.FigureFormat("svg"))
assert all(p.read_bytes().lstrip().startswith(b"<?xml") for p in svg), svg

from robotadapt.cli import main

study = out / "study.toml"
study.write_text('[robot]\\nkind = "one_link"\\n[plant]\\nphi = [1.0, 1.0]\\n[trajectory]\\nkind = "sinusoid"\\n'
                 '[controller]\\nkind = "slotine_li"\\nLam = 5.0\\nKv = 10.0\\nGamma = 10.0\\n'
                 '[simulation]\\nt_final = 0.2\\n[study]\\n"controller.Kv" = [5.0, 20.0]\\n')
short = ["example-6.3.1", "--t-final", "0.2"]
for args in (["compare", *short, "--controllers", "slotine_li,pd", "--out", str(out / "compare")],
             ["sweep", *short, "--grid", "controller.Kv=5,10", "--workers", "1", "--out", str(out / "sweep")],
             ["run", str(study), "--out", str(out / "study")],
             ["pe", "example-6.5.2a", "--out", str(out / "pe")]):
    assert main(args) == 0, args
for name in ("compare/report.html", "compare/laws.png", "sweep/sweep.png", "study/study_controller_Kv.png", "pe/pe.png"):
    assert (out / name).is_file(), name

import robotadapt.report.identification_figures  # noqa: F401 -- every report module, imported: none switches
import robotadapt.report.mujoco  # noqa: F401
import robotadapt.report.tune_figures  # noqa: F401
import robotadapt.report.video  # noqa: F401
"""


def _run(code: str, out: Path) -> None:
    p = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0 and p.stdout.strip().endswith("ok"), p.stderr[-4000:] or p.stdout[-2000:]


def test_drawing_neither_switches_the_backend_nor_imports_pyplot(tmp_path):
    """A script that never imports pyplot: after every figure, its backend is still its own, pyplot was never
    imported and no pyplot figure exists."""
    check = """
from matplotlib import _pylab_helpers

assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert "matplotlib.pyplot" not in sys.modules, "the package imported pyplot"
assert not _pylab_helpers.Gcf.get_all_fig_managers(), "the package made pyplot figures"
print("ok")
"""
    _run(USER + DRAW + check, tmp_path)


def test_drawing_leaves_a_notebooks_pyplot_figures_alone(tmp_path):
    """A notebook's session: pyplot imported on its backend, a figure open. Drawing the package's figures keeps that
    backend, keeps the figure open and current, and adds none to pyplot."""
    user = """
import matplotlib.pyplot as plt

mine = plt.figure()
"""
    check = """
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert plt.get_fignums() == [mine.number], plt.get_fignums()
assert plt.gcf() is mine
print("ok")
"""
    _run(USER + user + DRAW + check, tmp_path)
