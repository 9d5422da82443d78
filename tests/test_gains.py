"""Gain conditions of §7.2: ζ estimates bound the mismatch (7.2.9), and the checks follow (7.2.22)–(7.2.48)."""

import json

import numpy as np
import pytest

from robotadapt.cli import main
from robotadapt.gains import _mismatch, check, estimate_zeta, gain_report
from robotadapt.robots import TwoLinkArm
from robotadapt.scenarios import load
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


def test_book_gains_hold_and_small_gains_fail():
    s = load("example-7.2.1").setup
    assert gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final).all_hold
    s = load("example-7.2.1", ["controller.Kv=5", "controller.Kp=5"]).setup
    assert not gain_report(s.controller, s.plant.phi, s.trajectory, s.t_final).all_hold


def test_cli_json(capsys):
    assert main(["gains", "example-7.2.2", "--json", "--samples", "500"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["conditions"]) == {"7.2.22", "7.2.25", "7.2.48"} and len(out["zeta"]) == 4


@pytest.mark.parametrize("argv", [["gains", "example-6.3.1"], ["gains", "example-7.2.1", "--radius", "-1"]])
def test_cli_bad_input_exits_2(argv, capsys):
    assert main(argv) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
