"""Argument checking: as_gain, as_vector, as_scalar (and the ConfigError they raise)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from robotadapt.validation import ConfigError, as_gain, as_scalar, as_vector, check_names


def raises_naming(field: str):
    """A ConfigError whose message starts with the field name."""
    return pytest.raises(ConfigError, match=rf"^{re.escape(field)}: ")


# --------------------------------------------------------------------------------------------------------------------
# as_gain


def test_gain_scalar_is_k_times_identity():
    np.testing.assert_array_equal(as_gain(2.5, 3, "controller.Kv"), [[2.5, 0, 0], [0, 2.5, 0], [0, 0, 2.5]])
    np.testing.assert_array_equal(as_gain(7, 1, "controller.Kv"), [[7.0]])
    np.testing.assert_array_equal(as_gain(np.float32(3.0), 2, "controller.Kv"), [[3.0, 0.0], [0.0, 3.0]])


def test_gain_list_is_a_diagonal():
    np.testing.assert_array_equal(as_gain([1.0, 2.0], 2, "controller.Kv"), [[1.0, 0.0], [0.0, 2.0]])
    np.testing.assert_array_equal(as_gain((4, 5, 6), 3, "controller.Kv"), np.diag([4.0, 5.0, 6.0]))


def test_gain_matrix_is_kept():
    K = [[4.0, 1.0], [1.0, 3.0]]
    out = as_gain(K, 2, "controller.Kv")
    np.testing.assert_array_equal(out, K)
    assert out.dtype == np.float64
    assert out.shape == (2, 2)


@pytest.mark.parametrize(
    ("value", "why"),
    [
        pytest.param([[1.0, 0.5], [0.0, 1.0]], "symmetric", id="non-symmetric"),
        pytest.param([[1.0, 2.0], [2.0, 1.0]], "positive definite", id="indefinite"),
        pytest.param(-1.0, "positive definite", id="negative-scalar"),
        pytest.param(0.0, "positive definite", id="zero"),
        pytest.param([1.0, 0.0], "positive definite", id="semi-definite-diagonal"),
        pytest.param([1.0, 2.0, 3.0], "2 entries", id="list-too-long"),
        pytest.param(np.eye(3), "2x2", id="wrong-matrix-shape"),
        pytest.param(np.ones((2, 2, 2)), "2x2", id="3-d"),
        pytest.param(True, "number", id="bool"),
        pytest.param("1", "number", id="str"),
        pytest.param(b"1", "number", id="bytes"),
        pytest.param(None, "number", id="none"),
        pytest.param(["a", "b"], "number", id="list-of-str"),
        pytest.param(float("nan"), "finite", id="nan"),
        pytest.param([[1.0, 0.0], [0.0, float("inf")]], "finite", id="inf"),
        pytest.param([[1.0, 0.0], [0.0]], "number", id="ragged"),
    ],
)
def test_gain_rejections_name_the_field_and_the_reason(value, why):
    with raises_naming("controller.Kv") as info:
        as_gain(value, 2, "controller.Kv")
    assert info.value.field == "controller.Kv"
    assert why in info.value.reason


def test_gain_symmetry_tolerates_round_off_only():
    K = np.array([[2.0, 0.3], [0.3 * (1 + 1e-14), 1.0]])
    np.testing.assert_array_equal(as_gain(K, 2, "g"), K)
    with raises_naming("g"):
        as_gain(np.array([[2.0, 0.3], [0.3 * (1 + 1e-6), 1.0]]), 2, "g")


def test_semidefinite_gain_allows_zero_but_not_negative():
    np.testing.assert_array_equal(as_gain([1.0, 0.0], 2, "controller.Kp", semidefinite=True), [[1.0, 0.0], [0.0, 0.0]])
    np.testing.assert_array_equal(as_gain(0.0, 2, "controller.Kp", semidefinite=True), np.zeros((2, 2)))
    with raises_naming("controller.Kp") as info:
        as_gain([1.0, -1e-3], 2, "controller.Kp", semidefinite=True)
    assert "semidefinite" in info.value.reason
    with raises_naming("controller.Kp"):
        as_gain([[1.0, 0.5], [0.0, 1.0]], 2, "controller.Kp", semidefinite=True)


@pytest.mark.parametrize("fn", [lambda v: as_gain(v, 2, "controller.Kv"), lambda v: as_scalar(v, "controller.Kv")],
                         ids=["as_gain", "as_scalar"])
def test_numpy_bool_is_rejected_like_bool(fn):
    with raises_naming("controller.Kv"):
        fn(np.True_)


# --------------------------------------------------------------------------------------------------------------------
# as_vector


def test_vector_scalar_is_broadcast_and_list_is_kept():
    np.testing.assert_array_equal(as_vector(0.5, 3, "plant.phi"), [0.5, 0.5, 0.5])
    out = as_vector([1, 2], 2, "plant.phi")
    np.testing.assert_array_equal(out, [1.0, 2.0])
    assert out.dtype == np.float64


@pytest.mark.parametrize(
    ("value", "kwargs", "why"),
    [
        pytest.param(0.5, {"broadcast": False}, "a list of 2 numbers", id="scalar-without-broadcast"),
        pytest.param([1.0, 2.0, 3.0], {}, "shape (3,)", id="too-long"),
        pytest.param([[1.0, 2.0]], {}, "shape (1, 2)", id="2-d"),
        pytest.param([1.0, 0.0], {"positive": True}, "positive", id="not-positive"),
        pytest.param(-1.0, {"positive": True}, "positive", id="negative-broadcast"),
        pytest.param([1.0, float("nan")], {}, "finite", id="nan"),
        pytest.param(False, {}, "number", id="bool"),
        pytest.param("1, 2", {}, "number", id="str"),
    ],
)
def test_vector_rejections_name_the_field(value, kwargs, why):
    with raises_naming("plant.phi") as info:
        as_vector(value, 2, "plant.phi", **kwargs)
    assert why in info.value.reason


# --------------------------------------------------------------------------------------------------------------------
# as_scalar


def test_scalar_accepts_numbers():
    assert as_scalar(3, "sim.dt") == 3.0
    assert isinstance(as_scalar(np.float32(0.25), "sim.dt"), float)
    assert as_scalar(np.array(0.25), "sim.dt", positive=True) == 0.25
    assert as_scalar(0.0, "sim.dt", nonnegative=True) == 0.0
    assert as_scalar(-2.0, "sim.dt") == -2.0


@pytest.mark.parametrize(
    ("value", "kwargs", "why"),
    [
        pytest.param([1.0], {}, "single number", id="list"),
        pytest.param(0.0, {"positive": True}, "positive", id="zero-not-positive"),
        pytest.param(-1e-9, {"nonnegative": True}, "zero or positive", id="negative"),
        pytest.param(float("inf"), {}, "finite", id="inf"),
        pytest.param(True, {}, "number", id="bool"),
        pytest.param("0.1", {}, "number", id="str"),
        pytest.param(None, {}, "number", id="none"),
    ],
)
def test_scalar_rejections_name_the_field(value, kwargs, why):
    with raises_naming("sim.dt") as info:
        as_scalar(value, "sim.dt", **kwargs)
    assert info.value.field == "sim.dt"
    assert why in info.value.reason


# --------------------------------------------------------------------------------------------------------------------
# ConfigError and check_names


def test_config_error_is_a_value_error_with_field_and_reason():
    err = ConfigError("controller.Kv", "must be positive")
    assert isinstance(err, ValueError)
    assert str(err) == "controller.Kv: must be positive"
    assert (err.field, err.reason) == ("controller.Kv", "must be positive")
    assert str(ConfigError("", "no field")) == "no field"


def test_check_names_rejects_unknown_keys():
    check_names(["Kv", "Lam"], ["Kv", "Lam", "Gamma"], "controller")
    with raises_naming("controller.Kd") as info:
        check_names(["Kv", "Kd"], ["Kv", "Lam", "Gamma"], "controller")
    assert "Gamma, Kv, Lam" in info.value.reason


def test_a_config_error_of_any_kind_pickles_as_it_was():
    """A ConfigError comes back from a worker process (a fair comparison's tuning) with its message, field, reason and
    a subclass's own attributes, whatever its subclass's constructor takes."""
    import pickle
    from pathlib import Path

    from robotadapt.native.patience import Building
    from robotadapt.native.values import Unsupported

    for error in (ConfigError("controller.Kv", "must be positive"), Unsupported("primitive 'foo'"),
                  Building("simulation.backend", "being built", Path("/tmp/x.so"))):
        back = pickle.loads(pickle.dumps(error))
        assert type(back) is type(error) and str(back) == str(error) and vars(back) == vars(error)
