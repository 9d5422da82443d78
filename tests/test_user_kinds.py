"""A user's own kinds, named `"module:Class"` from a scenario without editing the package, and the warning when
"auto" steps a law JAX cannot trace with numpy."""

from __future__ import annotations

import re
import sys
import textwrap
import warnings

import numpy as np
import pytest

from robotadapt.sim import RK4, simulate
from robotadapt.sim.integrators import NotTraceableWarning
from robotadapt.studies.scenarios import load
from robotadapt.studies.scenarios.build import build, keys, kinds
from robotadapt.validation import ConfigError

LAW = '''
from dataclasses import dataclass
from typing import Any

import numpy as np

from robotadapt.controllers import Law
from robotadapt.controllers.base import slotine_li_regressor


@dataclass(frozen=True, eq=False)
class Gravityless(Law):
    """τ = K_v r: a PD on r = ė + Λe (Table 6.3.1's r), no estimate."""

    model: Any
    Kv: float
    Lam: float = 1.0
    phi_hat0: Any = None
    state_names = ()

    def initial_state(self, q0, dq0):
        return np.zeros(0)

    def phi_hat(self, x):
        return np.zeros(x.shape[:-1] + (self.model.p,))

    def __call__(self, t, x, q, dq, ref):
        _, r = slotine_li_regressor(self.model, np.eye(self.model.n) * self.Lam, q, dq, ref)
        return self.Kv * r, x
'''


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    (tmp_path / "mylaws.py").write_text(textwrap.dedent(LAW))
    monkeypatch.chdir(tmp_path)
    yield "mylaws"
    sys.modules.pop("mylaws", None)


def _scenario(tmp_path, controller: str) -> str:
    path = tmp_path / "s.toml"
    path.write_text(f'[robot]\nkind = "two_link"\n[plant]\nphi = [0.8, 2.3]\n[trajectory]\nkind = "sinusoid"\n'
                    f'[controller]\n{controller}\n[simulation]\nt_final = 0.05\n')
    return str(path)


def test_a_module_in_the_current_folder_is_a_controller_kind(user_module, tmp_path):
    res = load(_scenario(tmp_path, 'kind = "mylaws:Gravityless"\nKv = 30.0\nLam = 2.0')).run()
    assert res.status == "ok"
    # the torque is the law's K_v r, r = ė + Λe, written here from the logged state
    r = res.de + 2.0 * res.e
    assert np.allclose(res.tau, 30.0 * r, atol=1e-12)
    taken = keys("controller", "mylaws:Gravityless")  # the class's fields, less the model it takes first
    assert list(taken) == ["Kv", "Lam", "phi_hat0"] and taken["Lam"] == 1.0
    assert "mylaws:Gravityless" not in kinds("controller")  # nothing registered: docs/keys.md stays as it is


@pytest.mark.parametrize("controller, message", [
    ('kind = "mylaws:Gravityless"\nKv = 30.0\ngain = 1',
     r"^controller\.gain: unknown key; known keys here: Kv, Lam, phi_hat0$"),
    ('kind = "mylaws:Gravityless"', r"^controller\.Kv: missing; known keys here"),
    ('kind = "mylaws:Nothing"\nKv = 1', r"^controller\.kind: module 'mylaws' has no 'Nothing'$"),
    ('kind = "nosuchmodule:Law"', r"^controller\.kind: cannot import 'nosuchmodule' .* run from the folder that holds "
                                  r"nosuchmodule\.py$"),
    ('kind = "dead_zone"', r"^controller\.kind: expected one of .*slotine_li.*, or \"module:Class\" for your own; "
                           r"got 'dead_zone'$"),
])
def test_a_wrong_user_kind_is_one_line_naming_the_field(user_module, tmp_path, controller, message):
    with pytest.raises(ConfigError) as err:
        load(_scenario(tmp_path, controller)).run()
    assert len(str(err.value).splitlines()) == 1
    assert re.search(message, str(err.value)), str(err.value)


def test_a_user_kind_in_a_nested_table_takes_what_that_registry_takes(user_module):
    with pytest.raises(ConfigError, match=r"^controller\.law\.kind: module 'mylaws' has no 'NoSuchLaw'"):
        build("controller", {"kind": "passivity", "Kv": 1.0, "servo": {"kind": "pd", "Lam": 1.0},
                             "law": {"kind": "mylaws:NoSuchLaw"}}, "controller", load("example-6.3.1").setup.plant.model)


def test_auto_says_when_it_steps_a_law_jax_cannot_trace_with_numpy():
    from robotadapt.controllers import InertiaRelated
    from robotadapt.plant import Plant
    from robotadapt.robots import TwoLinkArm
    from robotadapt.trajectories import sinusoid

    class NumpyOnly(InertiaRelated):
        def __call__(self, t, x, q, dq, ref):
            tau, dx = super().__call__(t, x, q, dq, ref)
            return np.asarray(tau), dx

    arm = TwoLinkArm()
    law = NumpyOnly(arm, Lam=2.5, Kv=10.0, Gamma=20.0, phi_hat0=[0.0, 0.0])
    with pytest.warns(NotTraceableWarning, match=r"NumpyOnly on TwoLinkArm cannot be compiled with JAX .*stepped "
                                                 r"with numpy instead .*docs/tutorial\.md#traceable"):
        res = simulate(Plant(arm, [0.8, 2.3]), law, sinusoid(2), t_final=3.0, integrator=RK4(1e-3))
    assert res.info["backend"] == "numpy" and res.status == "ok"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError, match=r"^simulation\.backend: NumpyOnly"):
            simulate(Plant(arm, [0.8, 2.3]), law, sinusoid(2), t_final=3.0, integrator=RK4(1e-3, backend="jax"))
