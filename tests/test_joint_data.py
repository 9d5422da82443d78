"""Robot logs as they come (robotadapt.analysis.joint_data): jittered time stamps resampled onto a uniform grid and said
so in one note, gaps too long to bridge and time going back refused naming where, exact repeats dropped, a uniform log
passed on untouched."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from robotadapt.analysis.joint_data import MAX_GAP_PERIODS, read
from robotadapt.cli import main
from robotadapt.studies.scenarios import load
from robotadapt.trajectories import fourier
from robotadapt.validation import ConfigError

W1, W2 = 2 * np.pi * 0.5, 2 * np.pi * 2.1  # rad/s: the log's two frequencies (an exciting trajectory's range)


def q_true(t: np.ndarray) -> np.ndarray:
    return np.column_stack([np.sin(W1 * t), 0.3 * np.cos(W2 * t + 1.0)])


def dq_true(t: np.ndarray) -> np.ndarray:
    return np.column_stack([W1 * np.cos(W1 * t), -0.3 * W2 * np.sin(W2 * t + 1.0)])


def tau_true(t: np.ndarray) -> np.ndarray:
    return np.column_stack([2.0 + 5.0 * np.sin(W1 * t + 0.3), -1.0 + 2.0 * np.cos(W2 * t)])


def write_csv(path: Path, t: np.ndarray, q: np.ndarray, tau: np.ndarray, dq: np.ndarray | None = None) -> Path:
    cols = {"t": t, "q1": q[:, 0], "q2": q[:, 1], "tau1": tau[:, 0], "tau2": tau[:, 1]}
    if dq is not None:
        cols |= {"dq1": dq[:, 0], "dq2": dq[:, 1]}
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.17g")
    return path


def jittered(n: int = 3000, low: float = 0.7e-3, high: float = 9e-3, seed: int = 5) -> np.ndarray:
    """Time stamps whose periods are drawn uniformly from [low, high] s."""
    return np.r_[0.0, np.cumsum(np.random.default_rng(seed).uniform(low, high, n))]


def test_a_jittered_log_is_resampled_to_the_true_signal_and_says_so_in_one_line(tmp_path):
    """Periods of 0.7–9 ms, random: one uniform grid at the median rate rounded (4.8 ms → 208 Hz), q and the logged q̇
    within 1e-6 of the true signal (cubic spline), τ within 1e-3 of its amplitude (linear), one note naming both."""
    t = jittered()
    data = read(write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t), dq_true(t)), 2)
    steps = np.diff(t)
    rate = float(f"{1 / np.median(steps):.3g}")
    assert rate == 208.0
    assert np.allclose(np.diff(data.t), 1 / rate, rtol=0, atol=1e-12) and data.t[0] == 0.0 and data.t[-1] <= t[-1]
    assert data.t.size == int((t[-1] - t[0]) * rate) + 1
    assert np.max(np.abs(data.q - q_true(data.t))) < 1e-6
    assert data.dq is not None and np.max(np.abs(data.dq - dq_true(data.t))) < 1e-5 * np.max(np.abs(dq_true(t)))
    assert np.max(np.abs(data.tau - tau_true(data.t))) < 1e-3 * np.max(np.abs(tau_true(t)))
    (note,) = data.notes
    assert "\n" not in note and note.startswith("log.csv: time stamps jittered")
    assert f"sample period {np.min(steps) * 1e3:.3g} ms to {np.max(steps) * 1e3:.3g} ms" in note
    assert f"median {np.median(steps) * 1e3:.3g} ms" in note
    assert f"resampled to a uniform 208 Hz, {t.size} → {data.t.size} samples" in note
    assert "q and q̇ by cubic spline, τ linearly" in note


def test_a_panda_log_at_1_khz_with_stamps_from_0_7_to_8_8_ms_is_read_at_1000_hz(tmp_path):
    """What a Panda's controller writes: mostly 1 ms, every hundredth period anywhere in 0.7–8.8 ms. Read (no longer
    refused) on a 1000-Hz grid, each of the 7 joints' q within 1e-6, τ within 1e-3 of its largest value (both worst
    across the 8.8-ms period: the spline's error grows as its fourth power, the line's as its square)."""
    rng = np.random.default_rng(7)
    steps = np.where(rng.random(5000) < 0.01, rng.uniform(0.7e-3, 8.8e-3, 5000), rng.normal(1e-3, 3e-5, 5000))
    steps[[100, 200]] = 0.7e-3, 8.8e-3
    t = np.r_[0.0, np.cumsum(steps)]
    q, tau = np.tile(q_true(t), (1, 4))[:, :7], np.tile(tau_true(t), (1, 4))[:, :7]
    header = ["t", *(f"q{i}" for i in range(1, 8)), *(f"tau{i}" for i in range(1, 8))]
    np.savetxt(tmp_path / "panda.csv", np.column_stack([t, q, tau]), delimiter=",", header=",".join(header),
               comments="", fmt="%.17g")
    data = read(tmp_path / "panda.csv", 7)
    assert np.allclose(np.diff(data.t), 1e-3, rtol=0, atol=1e-12) and data.dq is None
    assert np.max(np.abs(data.q - np.tile(q_true(data.t), (1, 4))[:, :7])) < 1e-6
    assert np.max(np.abs(data.tau - np.tile(tau_true(data.t), (1, 4))[:, :7])) < 1e-3 * np.max(np.abs(tau))
    (note,) = data.notes
    assert "sample period 0.7 ms to 8.8 ms (median 1 ms" in note and "uniform 1000 Hz" in note
    assert "q by cubic spline, τ linearly" in note


def test_identify_on_a_jittered_log_finds_the_parameters(tmp_path):
    """`robotadapt identify` on Example 6.3.1's arm logged with stamps 0.7–9 ms apart (an exciting Fourier path of 1 Hz
    at most, τ = Y φ): the resampled log gives φ within 1e-3 (2.2e-4 measured; τ's linear interpolation is the error)."""
    import json

    setup = load("example-6.3.1").setup
    t = jittered(1700, seed=3)
    a, b = np.random.default_rng(27).uniform(-0.4, 0.4, (2, 2, 4))
    ref = fourier(2, 4.0, a, b, [0.0, -0.785])(t)
    tau = np.asarray(setup.controller.model.regressor(ref.q_des, ref.dq_des, ref.dq_des, ref.ddq_des)) @ setup.plant.phi
    path = write_csv(tmp_path / "log.csv", t, ref.q_des, tau, ref.dq_des)
    assert main(["identify", str(path), "--robot", "example-6.3.1", "--out", str(tmp_path / "id"), "--no-plots"]) == 0
    phi = np.array(json.loads((tmp_path / "id" / "identified.json").read_text())["phi"])
    assert np.max(np.abs(phi / setup.plant.phi - 1)) < 1e-3


def test_a_uniform_log_with_samples_lost_is_put_back_on_its_own_rate(tmp_path):
    """1250 Hz with every 50th sample missing (a lost packet): the rate chosen is 1250 Hz, the grid falls on the logged
    stamps, so each kept sample comes back as logged and only the lost ones are interpolated."""
    t = np.arange(1000) / 1250
    kept = np.arange(1000) % 50 != 25
    data = read(write_csv(tmp_path / "log.csv", t[kept], q_true(t)[kept], tau_true(t)[kept], dq_true(t)[kept]), 2)
    assert "uniform 1250 Hz" in data.notes[0] and data.t.size == 1000
    assert np.allclose(data.t, t, rtol=0, atol=1e-12)
    assert np.allclose(data.q[kept], q_true(t)[kept], rtol=0, atol=1e-12)
    assert np.allclose(data.tau[kept], tau_true(t)[kept], rtol=0, atol=1e-12)
    assert np.max(np.abs(data.q - q_true(t))) < 1e-9


def test_logged_velocities_are_interpolated_not_made_from_positions(tmp_path):
    """A q̇ column that is no derivative of q (a constant) comes back as logged: q̇ is never differentiated here."""
    t = jittered(400)
    dq = np.full((t.size, 2), [0.25, -4.0])
    data = read(write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t), dq), 2)
    assert data.dq is not None and np.allclose(data.dq, [0.25, -4.0], rtol=0, atol=1e-12)


def test_torque_is_interpolated_linearly_so_a_step_does_not_overshoot(tmp_path):
    """τ stepping from −1 to +1 (Coulomb friction at a velocity reversal): every resampled value stays within [−1, 1] and
    on the chord of its two logged neighbours."""
    t = jittered(600)
    tau = np.where(t[:, None] < t[300], -1.0, 1.0) * np.ones((1, 2))
    data = read(write_csv(tmp_path / "log.csv", t, q_true(t), tau), 2)
    assert np.all(np.abs(data.tau) <= 1.0)
    k = np.clip(np.searchsorted(t, data.t, side="right") - 1, 0, t.size - 2)
    chord = tau[k, 0] + (data.t - t[k]) / (t[k + 1] - t[k]) * (tau[k + 1, 0] - tau[k, 0])
    assert np.allclose(data.tau[:, 0], chord, rtol=0, atol=1e-12)


def test_a_uniform_log_is_passed_through_bit_identical(tmp_path):
    """Uniform stamps (and stamps within 1 % of uniform) are not resampled: every value as the file has it, no note."""
    t = np.arange(500) * 2e-3
    path = write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t), dq_true(t))
    values = np.loadtxt(path, delimiter=",", skiprows=1)
    data = read(path, 2)
    assert data.notes == ()
    assert np.array_equal(data.t, values[:, 0]) and np.array_equal(data.q, values[:, 1:3])
    assert np.array_equal(data.tau, values[:, 3:5]) and data.dq is not None and np.array_equal(data.dq, values[:, 5:7])
    wobbly = t + np.random.default_rng(0).uniform(-4e-6, 4e-6, t.size)  # ±0.4 % of the period
    data = read(write_csv(tmp_path / "wobbly.csv", wobbly, q_true(t), tau_true(t)), 2)
    assert data.notes == () and np.array_equal(data.t, np.loadtxt(tmp_path / "wobbly.csv", delimiter=",",
                                                                   skiprows=1)[:, 0])


def test_a_result_npz_of_ours_reads_as_before(tmp_path):
    t = np.arange(300) * 1e-3
    np.savez(tmp_path / "result.npz", t=t, q=q_true(t), dq=dq_true(t), tau=tau_true(t))
    data = read(tmp_path / "result.npz", 2)
    assert data.notes == () and np.array_equal(data.t, t) and np.array_equal(data.q, q_true(t))
    assert data.slice(slice(10, 20)).notes == () and data.slice(slice(10, 20)).t.size == 10


def test_a_gap_too_long_to_bridge_is_refused_naming_its_time(tmp_path):
    """A 0.2-s hole in a 1-kHz log: one line naming where (time and samples) and how long, and the fix; allowed with a
    larger max_gap."""
    t = np.arange(2000) * 1e-3
    t[1234:] += 0.2
    path = write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t))
    with pytest.raises(ConfigError) as err:
        read(path, 2)
    message = str(err.value)
    assert message.startswith("DATA: log.csv: a gap of 201 ms in the time stamps at t = 1.233 s (samples 1233 to 1234)")
    assert "201 median periods of 1 ms" in message and "--max-gap 0.22" in message and "\n" not in message
    data = read(path, 2, max_gap=0.25)
    assert np.allclose(np.diff(data.t), 1e-3, rtol=0, atol=1e-12) and "uniform 1000 Hz" in data.notes[0]


def test_the_default_gap_limit_is_ten_median_periods(tmp_path):
    t = np.arange(400) * 1e-3
    t[200:] += (MAX_GAP_PERIODS - 1.5) * 1e-3  # a period of 9.5 ms: bridged
    assert "uniform 1000 Hz" in read(write_csv(tmp_path / "a.csv", t, q_true(t), tau_true(t)), 2).notes[0]
    t[200:] += 1e-3  # 10.5 ms: refused
    with pytest.raises(ConfigError, match=r"a gap of 10\.5 ms .* at t = 0\.199 s"):
        read(write_csv(tmp_path / "b.csv", t, q_true(t), tau_true(t)), 2)


def test_exact_repeats_are_dropped_with_a_note(tmp_path):
    """Samples repeated whole (time and values), as a logger writing one sample twice does: dropped, one note counting
    them and naming the first; the rest as if they had never been there (here a uniform log: untouched)."""
    t = np.arange(300) * 1e-3
    rows = np.r_[np.arange(300), [50, 50, 120]]
    rows.sort()
    data = read(write_csv(tmp_path / "log.csv", t[rows], q_true(t)[rows], tau_true(t)[rows]), 2)
    assert data.notes == ("log.csv: dropped 3 samples repeating the previous one exactly (time and values; the first "
                          "at sample 51, t = 0.05 s)",)
    clean = read(write_csv(tmp_path / "clean.csv", t, q_true(t), tau_true(t)), 2)
    assert np.array_equal(data.t, clean.t) and np.array_equal(data.q, clean.q) and np.array_equal(data.tau, clean.tau)


def test_a_repeated_stamp_with_other_values_is_refused_naming_it(tmp_path):
    t = np.arange(300) * 1e-3
    t[101] = t[100]
    with pytest.raises(ConfigError) as err:
        read(write_csv(tmp_path / "log.csv", t, q_true(np.arange(300) * 1e-3), tau_true(t)), 2)
    assert str(err.value) == ("DATA: log.csv: samples 100 and 101 share the time stamp t = 0.1 s but differ in value: "
                              "keep the right one (or fix the clock that stamped them)")


def test_time_going_back_is_refused_naming_the_sample(tmp_path):
    t = jittered(500)
    t[321] = t[319] - 1e-4
    with pytest.raises(ConfigError) as err:
        read(write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t)), 2)
    assert str(err.value) == (f"DATA: log.csv: time does not increase at sample 321 (t = {t[320]:.6g} then "
                              f"{t[321]:.6g}): sort the rows and drop repeated samples")


@pytest.mark.parametrize("kwargs, words", [
    ({"topic": "/joint_states"}, "DATA: a topic ('/joint_states') was given but 'log.csv' is no ROS bag"),
    ({"max_gap": 0.0}, "max_gap: the longest gap bridged must be a positive number of seconds, got 0.0"),
])
def test_options_that_do_not_apply_are_refused(tmp_path, kwargs, words):
    t = np.arange(100) * 1e-3
    with pytest.raises(ConfigError, match=re.escape(words)):
        read(write_csv(tmp_path / "log.csv", t, q_true(t), tau_true(t)), 2, **kwargs)


def test_a_file_of_another_kind_is_refused_naming_the_kinds(tmp_path):
    (tmp_path / "log.txt").write_text("t,q1\n")
    with pytest.raises(ConfigError, match=r"a \.csv file or a ROS bag \(folder, \.db3, \.mcap or \.bag\), got 'log\.txt'"):
        read(tmp_path / "log.txt", 2)
    with pytest.raises(ConfigError, match="no such file or folder"):
        read(tmp_path / "nowhere.csv", 2)


def test_a_bag_without_rosbags_installed_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.typesys", None)
    (tmp_path / "bag").mkdir()
    with pytest.raises(ConfigError) as err:
        read(tmp_path / "bag", 2)
    assert str(err.value) == ("DATA: reading the ROS bag 'bag' needs the rosbags package: pip install rosbags (or the "
                              "[identify] extra)")
