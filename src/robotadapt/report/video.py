"""A run as a movie: the arm as it moved and, as a translucent ghost, the desired pose, rendered off-screen by MuJoCo and
written as MP4 (imageio with its ffmpeg) or, without ffmpeg, as a GIF (Pillow).

Only rendering needs OpenGL: the plant imports MuJoCo without a GL backend (:func:`~robotadapt.plant.mujoco.load_mujoco`)
and :func:`gl_backend` picks one right before the first renderer: the user's MUJOCO_GL, else GLFW on a display, else
OSMesa on the CPU (`apt-get install libosmesa6`). Without a working backend `--video` is a ConfigError (`GL_FIX`).
"""

from __future__ import annotations

import importlib
import os
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..files import atomic_write
from ..plant.mujoco import MujocoPlant, load_mujoco
from ..robots import OneLinkArm, PolarArm, TwoLinkArm
from ..sim.result import SimulationResult
from ..validation import ConfigError

GHOST_RGBA = (0.2, 0.8, 0.3, 0.35)  # the desired pose: translucent green
GL_FIX = "install an OpenGL backend: apt-get install libosmesa6, or set MUJOCO_GL=egl"


def _no_gl(backend: str, exc: BaseException) -> ConfigError:
    """The `--video` error: MuJoCo cannot draw with `backend` (MUJOCO_GL's value) because of `exc`."""
    if isinstance(exc, AttributeError):  # PyOpenGL without its library: "'NoneType' object has no attribute ..."
        reason = "its OpenGL library does not load"
    else:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return ConfigError("--video", f"MuJoCo cannot render off-screen with MUJOCO_GL={backend or 'glfw'} ({reason}); "
                       f"{GL_FIX}")


def gl_backend(mj: Any) -> str:
    """Give MuJoCo's renderer an OpenGL backend, once: the user's MUJOCO_GL, else "glfw" where DISPLAY is set, else
    "osmesa"; returns it. MuJoCo chooses the backend when its `gl_context` module runs, which the plant's import of
    MuJoCo made choose none: it is run again here with MUJOCO_GL set for it (the user's environment is left as it was).
    A backend that does not load is a ConfigError naming `--video` and the fix."""
    backend = os.environ.get("MUJOCO_GL", "" if os.environ.get("DISPLAY") else "osmesa")
    if getattr(mj, "Renderer", None) is None:  # MuJoCo's rendering module did not import
        raise _no_gl(backend, ImportError("mujoco.Renderer is missing"))
    context = sys.modules[mj.Renderer.__module__].gl_context  # the module whose GLContext the Renderer creates
    if getattr(context, "GLContext", None) is not None:
        return backend
    user = os.environ.get("MUJOCO_GL")
    os.environ["MUJOCO_GL"] = backend
    try:
        importlib.reload(context)
    except (ImportError, AttributeError, OSError, RuntimeError) as exc:  # PyOpenGL without libOSMesa: AttributeError
        raise _no_gl(backend, exc) from None
    finally:
        if user is None:
            os.environ.pop("MUJOCO_GL", None)
    if getattr(context, "GLContext", None) is None:  # MUJOCO_GL=disable
        raise _no_gl(backend, RuntimeError("no GL context"))
    return backend


def renderer(mj: Any, model: Any, height: int, width: int) -> Any:
    """A `mujoco.Renderer` of `model` (:func:`gl_backend` first); no working OpenGL is a ConfigError naming `--video`."""
    backend = gl_backend(mj)
    try:
        with warnings.catch_warnings():  # GLFW without a display warns before it fails: the error says it all
            warnings.simplefilter("ignore")
            return mj.Renderer(model, height, width)
    except Exception as exc:  # no context: mujoco.FatalError, RuntimeError, GLFW's or PyOpenGL's errors
        raise _no_gl(backend, exc) from None


def check_rendering() -> None:
    """Fail now, before a run, where `--video` could not draw: a renderer of an empty model, opened and closed."""
    mj = load_mujoco()
    renderer(mj, mj.MjModel.from_xml_string("<mujoco/>"), 16, 16).close()


def _camera(mj: Any, model: Any, data: Any, plant: MujocoPlant) -> Any:
    """A free camera on the whole arm (`data` at its initial pose): the book's planar arms seen from +z (y up, gravity
    down the picture), a 3-D arm from the front and a little above."""
    camera = mj.MjvCamera()
    camera.type = mj.mjtCamera.mjCAMERA_FREE
    mj.mj_kinematics(model, data)
    reach = float(np.linalg.norm(data.xpos[1:], axis=1).max()) + 0.2
    if isinstance(plant.model, TwoLinkArm | PolarArm | OneLinkArm):
        reach = float(getattr(plant.model, "l1", 1.0) + getattr(plant.model, "l2", 0.0))
        camera.lookat[:], camera.distance, camera.azimuth, camera.elevation = (0.0, 0.0, 0.0), 2.8 * reach, 90.0, -90.0
    else:
        camera.lookat[:] = (0.0, 0.0, 0.4 * reach)
        camera.distance, camera.azimuth, camera.elevation = 1.7 * reach, 150.0, -15.0
    return camera


def frames(result: SimulationResult, plant: MujocoPlant, times: Any, size: tuple[int, int] = (640, 480)) -> list[Any]:
    """RGB frames (height, width, 3) of the run at `times` (s): the arm at q(t) and the ghost at q_des(t), both
    interpolated between logged samples."""
    mj = load_mujoco()
    model = plant.engine[0]
    width, height = size
    model.vis.global_.offwidth, model.vis.global_.offheight = max(width, 640), max(height, 480)
    drawing = renderer(mj, model, height, width)
    actual, ghost = mj.MjData(model), mj.MjData(model)
    camera, option, perturb = _camera(mj, model, actual, plant), mj.MjvOption(), mj.MjvPerturb()
    n, out = result.q.shape[1], []
    with drawing:
        for t in np.atleast_1d(times):
            for data, series in ((actual, result.q), (ghost, result.q_des)):
                data.qpos[:] = plant.qpos(np.array([np.interp(t, result.t, series[:, i]) for i in range(n)]))
                mj.mj_kinematics(model, data)
            drawing.update_scene(actual, camera)
            scene = drawing.scene
            first = scene.ngeom
            mj.mjv_addGeoms(model, ghost, option, perturb, mj.mjtCatBit.mjCAT_DYNAMIC, scene)
            for geom in range(first, scene.ngeom):
                scene.geoms[geom].rgba[:] = GHOST_RGBA
            out.append(drawing.render().copy())
    return out


def save_video(result: SimulationResult, plant: MujocoPlant, path: Path, fps: float = 30.0) -> Path:
    """Write the run's movie in real time to `path` (`.mp4`; a `.gif` when the suffix says so or ffmpeg is missing);
    returns the path written."""
    images = frames(result, plant, np.arange(0.0, result.t[-1] + 1e-12, 1.0 / fps))
    try:
        import imageio.v2 as imageio
        import imageio_ffmpeg  # noqa: F401 -- the MP4 writer's ffmpeg
    except ImportError:
        path = path.with_suffix(".gif")
    if path.suffix.lower() == ".gif":
        from PIL import Image

        pictures = [Image.fromarray(image) for image in images]
        atomic_write(path, lambda f: pictures[0].save(f, format="GIF", save_all=True, append_images=pictures[1:],
                                                      duration=round(1000 / fps), loop=0), binary=True)
        return path
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")  # ffmpeg writes a file by name: rename when done
    imageio.mimwrite(partial, images, fps=fps, codec="libx264", macro_block_size=8)
    os.replace(partial, path)
    return path
