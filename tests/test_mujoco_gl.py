"""MuJoCo without OpenGL (issue 22, item 9): a run that draws nothing needs no GL backend; `--video` without one is one
line and exit 2 naming the fix.

Each case is a fresh `robotadapt run` process on a machine made to look as if it had neither libOSMesa nor libEGL: a
sitecustomize makes ctypes refuse to load them (PyOpenGL loads its platform's library through ctypes), no DISPLAY.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

NO_GL = '''"""No OSMesa, no EGL: ctypes cannot load them."""
import ctypes

_load = ctypes.CDLL.__init__


def _refuse(self, name, *args, **kwargs):
    if name and ("OSMesa" in str(name) or "EGL" in str(name)):
        raise OSError(f"{name}: cannot open shared object file: No such file or directory")
    _load(self, name, *args, **kwargs)


ctypes.CDLL.__init__ = _refuse
'''


def run_without_gl(tmp_path: Path, *extra: str, mujoco_gl: str | None = None) -> subprocess.CompletedProcess:
    """`robotadapt run example-6.3.1` stepped by MuJoCo for 0.1 s, with OSMesa and EGL hidden."""
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text(NO_GL)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MUJOCO_GL",
                                                            "PYOPENGL_PLATFORM")}
    env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [os.environ.get("PYTHONPATH")])])
    if mujoco_gl is not None:
        env["MUJOCO_GL"] = mujoco_gl
    return subprocess.run([sys.executable, "-m", "robotadapt", "run", "example-6.3.1", "--set", "plant.engine=mujoco",
                           "--t-final", "0.1", "--no-plots", "--out", str(tmp_path / "out"), *extra],
                          capture_output=True, text=True, env=env, timeout=120)


@pytest.mark.parametrize("mujoco_gl", [None, "osmesa"])
def test_a_run_that_draws_nothing_needs_no_opengl(tmp_path: Path, mujoco_gl: str | None) -> None:
    """MuJoCo steps the arm without any GL library, whatever MUJOCO_GL names (the user's choice is for drawing)."""
    done = run_without_gl(tmp_path, mujoco_gl=mujoco_gl)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    assert (tmp_path / "out" / "result.npz").is_file()


@pytest.mark.parametrize(("mujoco_gl", "named"), [(None, "osmesa"), ("egl", "egl")])
def test_video_without_opengl_is_one_line_naming_the_fix(tmp_path: Path, mujoco_gl: str | None, named: str) -> None:
    """`--video` with no backend that loads: exit 2 before the run, one line naming `--video`, the backend tried and
    both fixes (libosmesa6, MUJOCO_GL=egl)."""
    done = run_without_gl(tmp_path, "--video", mujoco_gl=mujoco_gl)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("robotadapt: error: --video: "), lines[0]
    assert f"MUJOCO_GL={named}" in lines[0]
    assert "apt-get install libosmesa6" in lines[0] and "MUJOCO_GL=egl" in lines[0]
    assert not (tmp_path / "out").exists()  # refused before the simulation
