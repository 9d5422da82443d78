"""Scenario keys: the generated reference (docs/keys.md) is current, a section's key errors come in one message, the
per-parameter shapes name the parameters, a per-parameter Γ, and the written scenario holds every value used."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from robotadapt.studies.scenarios import load
from robotadapt.studies.scenarios.build import REGISTRIES, keys, kinds, setup
from robotadapt.validation import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _generator():
    spec = importlib.util.spec_from_file_location("docs_generate_keys", DOCS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_keys_page_is_current():
    """Regenerate with `python docs/generate.py` when this fails."""
    assert (DOCS / "keys.md").read_text(encoding="utf-8") == _generator().keys_page(), "docs/keys.md is out of date"


def test_the_keys_page_lists_every_key_of_every_kind_with_a_meaning():
    text = (DOCS / "keys.md").read_text(encoding="utf-8")
    for registry in REGISTRIES:
        for kind in kinds(registry):
            assert f'### kind = "{kind}"' in text
            for key in keys(registry, kind):
                assert f"| `{key}` |" in text
    for key in ("n_links", "lengths", "masses", "rods", "model", "Ka", "a", "backend", "torque_limit", "k_t", "com"):
        row = next(line for line in text.splitlines() if line.startswith(f"| `{key}` |"))
        assert row.split("|")[2].strip() != "—", row  # a meaning
    assert '`"auto"`' in text


def _two_link(**controller):
    return {"robot": {"kind": "two_link"}, "plant": {"phi": [0.8, 2.3]}, "trajectory": {"kind": "sinusoid"},
            "controller": {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 1.0, **controller},
            "simulation": {"t_final": 0.01}}


def test_every_unknown_and_missing_key_of_a_section_in_one_message():
    data = _two_link()
    data["controller"] = {"kind": "slotine_li", "lam": 5.0, "kv": 10.0, "Gamma": 1.0}
    with pytest.raises(ConfigError) as err:
        setup(data)
    assert err.value.field == "controller"
    assert "unknown keys lam, kv; missing keys Lam, Kv; known keys here:" in str(err.value)
    data = _two_link()
    data["simulation"] = {"dtt": 1e-3, "tfinal": 1.0}
    with pytest.raises(ConfigError, match=r"^simulation: unknown keys dtt, tfinal; missing key t_final"):
        setup(data)
    data = _two_link()
    data["plant"]["motor"] = {"R": 1.0}
    with pytest.raises(ConfigError, match=r"^plant\.motor: missing keys L, k_t, k_b; known keys"):
        setup(data)


def test_a_single_unknown_key_still_names_itself():
    data = _two_link(Kx=1.0)
    with pytest.raises(ConfigError, match=r"^controller\.Kx: unknown key; known keys here"):
        setup(data)


def test_a_wrong_length_of_parameters_names_the_length_and_the_parameters():
    data = _two_link()
    data["plant"]["phi"] = [1.0]
    with pytest.raises(ConfigError, match=r"^plant\.phi: expected a list of 2 numbers, one per parameter in the order "
                                          r"m1, m2; got 1 number$"):
        setup(data)
    with pytest.raises(ConfigError, match=r"^controller\.phi_hat0: expected a list of 2 numbers, .* m1, m2; got 3"):
        setup(_two_link(phi_hat0=[0.0, 0.0, 0.0]))
    data = _two_link(phi_hat0=[0.0])
    data["robot"] = {"kind": "planar", "n_links": 4}
    data["plant"] = {"phi": [1.0]}
    data["controller"]["Lam"] = 5.0
    with pytest.raises(ConfigError, match=r"^plant\.phi: expected a list of (\d+) numbers, .*\.\.\. \(all \1: "
                                          r"docs/keys\.md, 'Parameter order'\)"):
        setup(data)


def test_a_plain_number_estimate_is_the_same_for_every_parameter():
    np.testing.assert_array_equal(setup(_two_link(phi_hat0=0)).controller.phi_hat0, [0.0, 0.0])
    np.testing.assert_array_equal(setup(_two_link(phi_hat0=1.5)).controller.phi_hat0, [1.5, 1.5])


@pytest.mark.parametrize("controller", [
    {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0},
    {"kind": "adaptive_computed_torque", "Kp": 25.0, "Kv": 10.0, "phi_hat0": [0.8, 2.3]},
    {"kind": "dcal", "Kv": 10.0, "Kp": 20.0, "Ka": 1.0},
])
def test_a_per_parameter_gamma_from_the_truth(controller):
    data = _two_link()
    data["controller"] = {**controller, "Gamma": {"scale": 10.0}}
    np.testing.assert_allclose(setup(data).controller.Gamma, np.diag(10 * (np.array([0.8, 2.3]) + 1e-3)))
    data["controller"]["Gamma"] = {"scale": 2.0, "eps": 0.5}
    np.testing.assert_allclose(setup(data).controller.Gamma, np.diag(2 * (np.array([0.8, 2.3]) + 0.5)))


def test_a_per_parameter_gamma_in_a_passivity_law_and_its_errors():
    data = _two_link()
    data["controller"] = {"kind": "passivity", "Kv": 10.0, "servo": {"kind": "pd", "Lam": 5.0},
                          "law": {"kind": "gradient", "Gamma": {"scale": 10.0}}}
    np.testing.assert_allclose(setup(data).controller.law.Gamma, np.diag(10 * (np.array([0.8, 2.3]) + 1e-3)))
    data["controller"]["law"]["Gamma"] = {"scal": 10.0}
    with pytest.raises(ConfigError, match=r"^controller\.law\.Gamma: unknown key scal; missing key scale"):
        setup(data)
    with pytest.raises(ConfigError, match=r"^controller\.Gamma\.scale: must be positive"):
        setup(_two_link(Gamma={"scale": -1.0}))


def test_the_written_scenario_holds_every_default_and_reproduces_the_run(monkeypatch):
    import robotadapt.robots.catalog as catalog
    import robotadapt.trajectories as trajectories

    data = {"robot": {"kind": "planar", "n_links": 2}, "trajectory": {"kind": "sinusoid"},
            "controller": {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 1.0},
            "plant": {}, "simulation": {"t_final": 0.01}}  # plant.phi: the arm's own, from masses and lengths
    first = setup(data)
    written = tomllib.loads(tomli_w.dumps(first.data))
    assert written["robot"]["masses"] == 1.0 and written["robot"]["g"] == 9.8
    assert written["trajectory"]["phase"] == 0.0 and written["simulation"]["dt"] == 1e-3
    monkeypatch.setattr(catalog.planar, "__defaults__", (2.0, 3.0, False, 1.0, None, None, None, "tree"))
    monkeypatch.setattr(trajectories.sinusoid, "__defaults__", (0.5, 2.0, 0.1, 0.2))
    changed = setup(tomllib.loads(tomli_w.dumps(data)))
    assert not np.allclose(changed.plant.phi, first.plant.phi)  # the defaults did change
    again = setup(written)
    np.testing.assert_allclose(again.plant.phi, first.plant.phi)
    np.testing.assert_allclose(again.plant.model.mass_matrix(np.ones(2), again.plant.phi),
                               first.plant.model.mass_matrix(np.ones(2), first.plant.phi))
    ref0, ref1 = first.trajectory(np.linspace(0, 1, 5)), again.trajectory(np.linspace(0, 1, 5))
    for a, b in zip(ref0, ref1, strict=True):
        np.testing.assert_allclose(a, b)


def test_the_scenario_text_is_the_written_one():
    scenario = load("example-6.3.1")
    written = tomllib.loads(scenario.text)
    assert written["trajectory"]["omega"] == 1.0 and written["controller"]["phi_hat0"] == [0.0, 0.0]
    assert written["robot"]["l1"] == 1.0 and written["simulation"]["method"] == "rk4"
