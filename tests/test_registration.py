"""A law registers itself in one place, its class body (robotadapt.controllers.registry): its scenario kind and other
names, its front-door name, its entries in the comparison's lineup and the gains a fair comparison tunes, all read from
there; a law defined here joins every one of them without touching the package, and leaves none behind when
unregistered. Every kind the package had before still builds from a scenario."""

from __future__ import annotations

import copy
import subprocess
import sys
from dataclasses import dataclass
from typing import Any

import pytest

import robotadapt as ra
import robotadapt.controllers as controllers
from robotadapt.controllers import Contender, InertiaRelated, registered
from robotadapt.controllers.registry import aliases, by_name, unregister
from robotadapt.studies.compare import contenders, lineup, tunable
from robotadapt.studies.scenarios import Scenario, load
from robotadapt.studies.scenarios.build import canonical_kind, keys, kinds, setup
from robotadapt.validation import ConfigError

KIND = "test_dead_zone"


@pytest.fixture
def law():
    """Slotine–Li with a (here unused) dead zone, registered under KIND by its class body alone; unregistered after."""

    @dataclass(frozen=True, eq=False)
    class DeadZoneTest(InertiaRelated):
        kind = KIND
        aliases = ("test_dz",)
        tuned = ("Lam", "Kv")
        lineup = (Contender(KIND, "Slotine–Li + dead zone", "a test", "Example 6.3.1",
                            {"kind": KIND, "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0, "delta": 0.1}, rank=65),)

        delta: Any = 0.0

    yield DeadZoneTest
    unregister(DeadZoneTest)
    _assert_gone(DeadZoneTest)


def _assert_gone(cls: type) -> None:
    assert KIND not in kinds("controller") and "test_dz" not in aliases("controller")
    assert KIND not in contenders() and cls not in registered().values()
    assert cls.__name__ not in dir(ra) and cls.__name__ not in ra.__all__ and cls.__name__ not in dir(controllers)
    with pytest.raises(AttributeError):
        getattr(ra, cls.__name__)
    with pytest.raises(ConfigError, match=r"^controller\.kind: expected one of .*slotine_li.*; got 'test_dz'"):
        setup(_data({"kind": "test_dz", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}))


def _data(controller: dict[str, Any], *sets: str) -> dict[str, Any]:
    data = copy.deepcopy(load("example-6.3.1", ["simulation.t_final=0.01", "simulation.backend='numpy'", *sets]).data)
    data.pop("study", None)
    data["controller"] = controller
    return data


def _scenario(name: str, data: dict[str, Any]) -> Scenario:
    return Scenario(name, data, setup(data))


def test_a_law_defined_outside_the_package_joins_every_table(law):
    # the scenario kind, its alias and its keys (the constructor's signature)
    assert KIND in kinds("controller") and canonical_kind("controller", "test_dz") == KIND
    assert "delta" in keys("controller", KIND)
    built = setup(_data({"kind": "test_dz", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0, "delta": 0.2}))
    assert type(built.controller) is law and built.data["controller"]["kind"] == "test_dz"
    # the front door and the package, by class name
    assert ra.DeadZoneTest is law and controllers.DeadZoneTest is law and by_name()["DeadZoneTest"] is law
    assert "DeadZoneTest" in dir(ra) and "DeadZoneTest" in ra.__all__ and "DeadZoneTest" in dir(controllers)
    # the comparison's lineup, at its rank, with the gains of its family (Slotine–Li's "6") from the scenario
    names = list(contenders())
    assert names[names.index("sigma") + 1] == KIND and names[names.index(KIND) + 1] == "composite"
    base = _scenario("base", _data({"kind": "slotine_li", "Lam": 2.5, "Kv": 20.0, "Gamma": 20.0,
                                    "phi_hat0": [0.5, 1.5]}))
    (entry,), skipped = lineup(base, [KIND])
    assert not skipped and entry.label == "Slotine–Li + dead zone"
    assert entry.source == "a test; gains: Example 6.3.1; from the scenario: Kv"
    assert entry.scenario.data["controller"]["kind"] == KIND and entry.scenario.data["controller"]["Kv"] == 20.0
    # what a fair comparison tunes: its `tuned`, not Γ
    assert tunable(entry.scenario) == ["controller.Lam", "controller.Kv"]


def test_unregistering_leaves_nothing_behind(law):
    unregister(law)
    _assert_gone(law)
    unregister(law)  # twice: nothing


def test_a_subclass_of_a_registered_law_does_not_register_itself():
    @dataclass(frozen=True, eq=False)
    class Variant(InertiaRelated):
        pass

    assert registered()["slotine_li"] is InertiaRelated and Variant not in registered().values()
    assert by_name()["InertiaRelated"] is InertiaRelated and "Variant" not in by_name()


def test_a_subclass_with_a_kind_of_its_own_has_its_own_names_and_entries():
    """It keeps its parent's gains (`tuned`, `family`), not its parent's alias or lineup entries."""
    variant = type("Variant", (InertiaRelated,), {"kind": "test_variant"})
    try:
        assert registered()["test_variant"] is variant and variant.aliases == () and variant.lineup == ()
        assert variant.tuned == InertiaRelated.tuned and variant.family == "6"
        assert aliases() == {"inertia_related": "slotine_li"} and list(contenders()).count("slotine_li") == 1
    finally:
        unregister(variant)
    assert "test_variant" not in kinds("controller")


def test_a_dataclass_field_named_kind_is_not_a_registration():
    @dataclass(frozen=True, eq=False)
    class WithKindField(InertiaRelated):
        kind: str = "a_field_value"

    assert "a_field_value" not in kinds("controller") and WithKindField not in registered().values()


@pytest.mark.parametrize("kind, message", [
    ("pd", r"the controller kind 'pd' is robotadapt\.controllers\.baseline\.PD's"),
    ("inertia_related", r"the controller kind 'inertia_related' is .*InertiaRelated's"),
    ("mylaws:Law", r"expected a name such as 'dead_zone'"),
])
def test_a_kind_taken_or_malformed_is_refused_where_the_class_is_defined(kind, message):
    with pytest.raises(TypeError, match=message):
        type("Clash", (InertiaRelated,), {"kind": kind})
    assert registered()["pd"].__name__ == "PD" and aliases()["inertia_related"] == "slotine_li"


def test_an_entry_of_another_kind_or_name_is_refused():
    entry = Contender("slotine_li", "again", "-", "-", {"kind": "test_other"})
    with pytest.raises(TypeError, match=r"the entry 'slotine_li' is InertiaRelated's"):
        type("Again", (InertiaRelated,), {"kind": "test_other", "lineup": (entry,)})
    with pytest.raises(TypeError, match=r"whose section has kind = 'test_other'"):
        type("Other", (InertiaRelated,), {"kind": "test_other", "lineup": (entry._replace(section={"kind": "pd"}),)})
    assert "test_other" not in kinds("controller")


PHI_HAT0 = [0.5, 1.5]  # M̂ > 0 for the fixed laws, inside adaptive computed torque's box
SECTIONS = {  # every controller kind the package had before its laws registered themselves, and the law kinds
    "slotine_li": {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0},
    "inertia_related": {"Lam": 2.5, "Kv": 10.0, "Gamma": 20.0},
    "computed_torque": {"Kp": 4.0, "Kv": 4.0, "phi_hat0": PHI_HAT0},
    "pd": {"Kp": 25.0, "Kv": 10.0},
    "pd_gravity": {"Kp": 25.0, "Kv": 10.0, "phi_hat0": PHI_HAT0},
    "adaptive_computed_torque": {"Kp": 125.0, "Kv": 50.0, "Gamma": 500.0, "phi_min": 0.1, "phi_max": 10.0,
                                 "phi_hat0": PHI_HAT0},
    "passivity": {"Kv": 10.0, "servo": {"kind": "pid", "Lam": 2.5, "Psi": 1.0}, "law": {"kind": "gradient", "Gamma": 20.0}},
    "composite": {"Lam": 2.5, "Kv": 10.0, "a": 1.0, "P0": 10.0},
    "sign_robust": {"kd": 2.2, "base": {"kind": "slotine_li", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}},
    "dcal": {"Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "Gamma": 20.0},
    "repetitive": {"Kv": 50.0, "Kp": 50.0, "Ka": 50.0, "kL": 50.0, "rounded_delay": True},  # dt does not divide 2π
}
CLASSES = {"slotine_li": "InertiaRelated", "inertia_related": "InertiaRelated", "computed_torque": "ComputedTorque",
           "pd": "PD", "pd_gravity": "PDGravity", "adaptive_computed_torque": "AdaptiveComputedTorque",
           "passivity": "PassivityBased", "composite": "Composite", "sign_robust": "SignRobust", "dcal": "DCAL",
           "repetitive": "Repetitive"}


def test_the_packaged_kinds_are_the_ones_before_in_their_order():
    assert kinds("controller")[:10] == ["slotine_li", "computed_torque", "pd", "pd_gravity", "adaptive_computed_torque",
                                        "passivity", "composite", "sign_robust", "dcal", "repetitive"]
    assert kinds("law")[:3] == ["gradient", "landau_pi", "sigma"]
    assert aliases() == {"inertia_related": "slotine_li"}
    assert list(contenders())[:12] == ["slotine_li", "computed_torque", "pd", "pd_gravity", "adaptive_computed_torque",
                                       "passivity", "passivity_pi", "sigma", "composite", "sign_robust", "dcal",
                                       "repetitive"]


@pytest.mark.parametrize("kind", list(SECTIONS))
def test_every_packaged_kind_builds_from_a_scenario_and_runs(kind):
    scenario = _scenario(kind, _data({"kind": kind, **SECTIONS[kind]}))
    assert type(scenario.setup.controller).__name__ == CLASSES[kind]
    assert scenario.run().status == "ok"


@pytest.mark.parametrize("law", [{"kind": "landau_pi", "K_I": 20.0, "F_p": 2.0},
                                 {"kind": "sigma", "Gamma": 20.0, "phi0": 3.0}])
def test_every_packaged_update_law_builds_from_a_scenario(law):
    section = {**SECTIONS["passivity"], "servo": {"kind": "pd", "Lam": 2.5}, "law": law}
    built = setup(_data({"kind": "passivity", **section})).controller.law
    assert type(built) is registered("law")[law["kind"]] and type(built).__name__ in ("LandauPI", "SwitchingSigma")


def test_finding_every_law_imports_no_jax_scipy_or_matplotlib():
    """The front door's first law imports the controllers package and every module of it, numpy only."""
    code = ("import sys; import robotadapt as ra; ra.InertiaRelated; names = dir(ra); "
            "from robotadapt.controllers.registry import registered; assert len(registered()) >= 10; "
            "heavy = [m for m in ('jax', 'scipy', 'matplotlib') if m in sys.modules]; assert not heavy, heavy; "
            "assert 'robotadapt.controllers.repetitive' in sys.modules; print('ok')")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


USER_MODULE = '''
from robotadapt.controllers import Contender, InertiaRelated


class Registered(InertiaRelated):
    kind = "test_user_module_law"
    lineup = (Contender("test_user_module_law", "a user's Slotine–Li", "-", "Example 6.3.1",
                        {"kind": "test_user_module_law", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}, rank=1000),)
'''


def test_a_scenarios_own_law_named_by_module_and_class_is_its_registered_entry(tmp_path, monkeypatch):
    """A scenario naming a user's class by "module:Class" imports its module, whose class registers itself: the
    comparison runs the scenario's law in place of that class's lineup entry, as for a packaged kind or an alias."""
    (tmp_path / "test_mylaws_registered.py").write_text(USER_MODULE, encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    try:
        for kind, entry in (("test_mylaws_registered:Registered", "test_user_module_law"),
                            ("inertia_related", "slotine_li")):
            base = _scenario("own", _data({"kind": kind, "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}))
            entries, _ = lineup(base, [entry])
            assert [(e.name, e.reference) for e in entries] == [(entry, True)]
            assert entries[0].scenario.data["controller"]["kind"] == kind
            assert "scenario" not in [e.name for e in lineup(base)[0]]
    finally:
        module = sys.modules.pop("test_mylaws_registered", None)
        if module is not None:
            unregister(module.Registered)
    assert "test_user_module_law" not in contenders()
