"""Gain conditions of §7.2: ζ estimates bound the mismatch (7.2.9), and the checks follow (7.2.22)–(7.2.48)."""

import json

import numpy as np
import pytest
from scipy.optimize import linprog

from robotadapt.analysis import gains
from robotadapt.analysis.gains import _mismatch, check, estimate_zeta, gain_report
from robotadapt.cli import main
from robotadapt.robots import TwoLinkArm
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import sinusoid

ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])


def test_zeta_bounds_fresh_samples():
    """The fitted bound holds (up to sampling) at points it was not fitted on."""
    traj = sinusoid(2)
    z = estimate_zeta(ARM, PHI, traj, 2 * np.pi, radius=0.5, samples=3000)
    rng = np.random.default_rng(7)
    t = rng.uniform(0, 2 * np.pi, 2000)
    e = rng.uniform(-0.5, 0.5, (2000, 2)) / np.sqrt(2)
    r = rng.uniform(-0.5, 0.5, (2000, 2)) / np.sqrt(2)
    y = _mismatch(ARM, PHI, traj(t), e, r)
    ne, nr = np.linalg.norm(e, axis=-1), np.linalg.norm(r, axis=-1)
    bound = z[0] * ne + z[1] * ne**2 + z[2] * nr + z[3] * nr * ne
    assert np.mean(y <= bound * 1.05 + 1e-9) > 0.99


def test_mismatch_vanishes_at_zero_error():
    traj = sinusoid(2)
    assert np.max(_mismatch(ARM, PHI, traj(np.linspace(0, 6, 50)), np.zeros((50, 2)), np.zeros((50, 2)))) < 1e-12


def test_conditions_arithmetic():
    c = check((4.0, 1.0, 2.0, 8.0), Kv=5.0, Kp=3.0, Ka=10.0)
    assert c["7.2.22"]["bound"] == 9.0 and c["7.2.22"]["holds"]          # 10 > 1 + 8
    assert c["7.2.25"]["bound"] == 2.25 and c["7.2.25"]["holds"]         # 3 > 4/2 + 1/4
    assert c["7.2.26"]["bound"] == 6.0 and not c["7.2.26"]["holds"]      # 5 > 2 + 2 + 2 fails
    c = check((4.0, 1.0, 2.0, 8.0), Kv=5.0, Kp=3.0, Ka=10.0, kL=4.0)
    assert "7.2.26" not in c and c["7.2.48"]["holds"]                    # 5 + 2 > 6


def test_book_gains_certified_and_small_gains_not():
    s = load("example-7.2.1").setup
    assert gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final).certified
    s = load("example-7.2.1", ["controller.Kv=5", "controller.Kp=5"]).setup
    report = gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final)
    assert not report.certified and report.margin < 0 and not all(c["holds"] for c in report.conditions.values())


def _by_hand(zeta, features, y, Kv, Kp, Ka, kL=None):
    """(7.2.9) at every sample (LP tolerance) and the strict conditions (7.2.22), (7.2.25), (7.2.26)/(7.2.48)."""
    z1, z2, z3, z4 = zeta
    admissible = min(zeta) >= 0 and np.all(features @ np.array(zeta) >= y - 1e-9)
    kv = Kv if kL is None else Kv + kL / 2
    return bool(admissible), Ka > z2 + z4 and Kp > z1 / 2 + z2 / 4 and kv > z1 / 2 + z3 + z4 / 4


def _synthetic(ne_nr):
    """Features (‖e‖, ‖e‖², ‖r‖, ‖r‖‖e‖) with one sample at (‖e‖, ‖r‖) = `ne_nr`, ‖Ỹ‖ = 1, and 200 slack samples."""
    rng = np.random.default_rng(3)
    ne, nr = np.concatenate([[ne_nr[0]], rng.uniform(0, 1, 200)]), np.concatenate([[ne_nr[1]], rng.uniform(0, 1, 200)])
    y = np.concatenate([[1.0], 0.5 * np.minimum(4 / 3 * ne[1:], nr[1:])])
    return np.stack([ne, ne**2, nr, nr * ne], axis=-1), y


@pytest.mark.parametrize("Kv, kL", [(0.9, None), (0.8, 0.2)])
def test_certify_finds_a_zeta_the_least_sum_fit_misses(Kv, kL):
    """At ‖e‖ = 0.75, ‖r‖ = 1 the least-sum fit takes ζ = (0, 0, 1, 0), so k_v (+ k_L/2) = 0.9 misses ζ3 = 1; but
    ζ = (4/3, 0, 0, 0) is admissible too and meets every condition (bounds 0, 2/3, 2/3). The old verdict, one check of
    the least-sum ζ, was a false negative."""
    features, y = _synthetic((0.75, 1.0))
    least = linprog([1.0, 1.25, 1.0, 1.25], A_ub=-features, b_ub=-y, bounds=[(0, None)] * 4, method="highs").x
    assert _by_hand(least, features, y, Kv, 1.0, 1.0, kL) == (True, False)  # what the old code checked
    assert _by_hand((4 / 3, 0, 0, 0), features, y, Kv, 1.0, 1.0, kL) == (True, True)
    certified, zeta, margin = gains.certify(features, y, Kv, 1.0, 1.0, kL)
    assert certified and margin > 0
    assert _by_hand(zeta, features, y, Kv, 1.0, 1.0, kL) == (True, True)


def test_not_certified_when_no_zeta_can_meet_the_conditions():
    """At ‖e‖ = ‖r‖ = 1 with ‖Ỹ‖ = 1, (7.2.9) needs ζ1 + ζ2 + ζ3 + ζ4 ≥ 1; the conditions give ζ2 + ζ4 < k_a,
    ζ1 < 2 k_p and ζ3 < k_v, so no ζ meets them when k_a + 2 k_p + k_v ≤ 1 (here 0.8)."""
    features, y = _synthetic((1.0, 1.0))
    Kv = Kp = Ka = 0.2
    certified, zeta, margin = gains.certify(features, y, Kv, Kp, Ka)
    assert not certified and margin < 0
    assert _by_hand(zeta, features, y, Kv, Kp, Ka) == (True, False)  # the representative ζ: admissible, misses
    # independent check: the largest absolute margin t with c_k·ζ + t ≤ g_k over admissible ζ is negative
    C = np.array([[0, 1, 0, 1], [0.5, 0.25, 0, 0], [0.5, 0, 1, 0.25]])
    A = np.block([[-features, np.zeros((len(y), 1))], [C, np.ones((3, 1))]])
    sol = linprog([0, 0, 0, 0, -1], A_ub=A, b_ub=np.concatenate([-y, [Ka, Kp, Kv]]),
                  bounds=[(0, None)] * 4 + [(None, 1)], method="highs")
    assert sol.success and sol.x[4] < 0


def test_book_gains_with_a_low_k_p_are_certified_by_another_zeta():
    """Example 7.2.1 with k_p = 30, k_v = 70: the least-sum ζ needs k_p > 33, yet a ζ with smaller ζ1 certifies."""
    s = load("example-7.2.1", ["controller.Kp=30", "controller.Kv=70"]).setup
    report = gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final)
    features, y = gains.sample_bound(s.controller.model, s.plant.phi, s.trajectory, s.trajectory.period)
    assert _by_hand(gains.fit_zeta(features, y), features, y, 70, 30, 50) == (True, False)
    assert report.certified and _by_hand(report.zeta, features, y, 70, 30, 50) == (True, True)
    assert all(c["holds"] for c in report.conditions.values())


def test_cli_json(capsys):
    assert main(["gains", "example-7.2.2", "--json", "--samples", "500"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["conditions"]) == {"7.2.22", "7.2.25", "7.2.48"} and len(out["zeta"]) == 4
    assert out["certified"] is True and out["margin"] > 0


def test_cli_text_says_certified_or_not(capsys):
    assert main(["gains", "example-7.2.1", "--samples", "500"]) == 0
    out = capsys.readouterr().out
    assert "certified for the sampled ball" in out and "not certified" not in out and "fail" not in out.lower()
    assert main(["gains", "example-7.2.1", "--samples", "500", "--set", "controller.Kp=5"]) == 0
    out = capsys.readouterr().out
    assert "not certified for the sampled ball" in out and "fail" not in out.lower()


@pytest.mark.parametrize("argv", [["gains", "example-6.3.1"], ["gains", "example-7.2.1", "--radius", "-1"]])
def test_cli_bad_input_exits_2(argv, capsys):
    assert main(argv) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
