"""The front door, `import robotadapt as ra` (docs/architecture.md): every name it lists is the object of its module,
importing the package changes nothing outside it and stays light, and the README's ten lines run through it."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import robotadapt as ra


@pytest.mark.parametrize("name", ra.__all__[1:])
def test_every_name_is_its_modules_object(name):
    value = getattr(ra, name)
    module = importlib.import_module(f"robotadapt.{ra._WHERE[name]}" if name in ra._WHERE else value.__module__)
    assert value is getattr(module, name)
    assert name in dir(ra)


def test_the_laws_are_the_registered_ones():
    """The laws and update laws at the front door are the classes registered in robotadapt.controllers, by name: no
    list of them anywhere else."""
    from robotadapt.controllers import registered

    laws = {cls.__name__ for table in ("controller", "law") for cls in registered(table).values()}
    assert {"InertiaRelated", "PassivityBased", "DCAL", "Repetitive", "Gradient", "LandauPI", "SwitchingSigma"} <= laws
    assert laws <= set(ra.__all__) and laws <= set(dir(ra))
    assert not laws & set(ra.EXPORTS["controllers"])


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'simulation'"):
        ra.simulation  # noqa: B018 - the old module paths went with version 0.1


def test_importing_the_package_touches_nothing_outside_it():
    """A fresh interpreter: `import robotadapt` leaves sys.meta_path as it was and imports neither JAX, scipy nor
    matplotlib (nor the controllers, nor importlib.metadata: the version is read when asked); the first `ra.load` does
    not switch JAX's settings before a program of the project needs JAX."""
    code = ("import sys; hooks = list(sys.meta_path); import robotadapt as ra; "
            "assert sys.meta_path == hooks, sys.meta_path; "
            "heavy = [m for m in ('jax', 'scipy', 'matplotlib', 'importlib.metadata') if m in sys.modules]; "
            "assert not heavy, heavy; "
            "assert 'robotadapt.controllers' not in sys.modules; "
            "assert all(hasattr(ra, k) for k in ('load', 'simulate', 'Plant', 'RK4', 'Sampled', 'metrics')); "
            "print('ok')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


def test_hello_world_through_the_front_door():
    """Example 6.3.1 with `ra.` names only, as the README shows it, against the scenario loaded by `ra.load`."""
    import numpy as np

    arm = ra.TwoLinkArm()
    ctrl = ra.InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    res = ra.simulate(ra.Plant(arm, phi=[0.8, 2.3]), ctrl, ra.sinusoid(2), t_final=2, integrator=ra.RK4(1e-3),
                      log_every=10)
    packaged = ra.load("example-6.3.1", ["simulation.t_final=2", "simulation.log_every=10",
                                         "simulation.backend='numpy'"]).run()
    assert res.status == "ok"
    np.testing.assert_allclose(res.q, packaged.q, rtol=1e-12, atol=1e-12)
    assert ra.metrics(res)["status"] == "ok"
