"""A run's end as a record (`robotadapt.sim.status.Status`): built once by the driver that stopped the run, rendered as
the text users read, carried to metrics.json as its fields; nothing parses the text back."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import robotadapt as ra
from robotadapt.sim.status import Status


def test_the_record_renders_as_todays_text_and_keeps_its_fields():
    at = Status.at(0.57, "state exceeded 1e+06 in magnitude")
    assert at == "diverged at t=0.57 s: state exceeded 1e+06 in magnitude"
    assert (at.code, at.t, at.t_end, at.reason) == ("diverged", 0.57, None, "state exceeded 1e+06 in magnitude")
    assert at.headline == "diverged at t=0.57 s"
    inside = Status.within(0.002, 0.001, "M̂ not positive definite: a: b")  # a reason may hold colons
    assert inside == "diverged within the step from 0.002 to 0.003 s: M̂ not positive definite: a: b"
    assert inside.headline == "diverged within the step from 0.002 to 0.003 s" and inside.t_end == pytest.approx(0.003)
    assert Status.ok() == "ok" and Status.ok().headline == "ok" and Status.ok().code == "ok"
    back = pickle.loads(pickle.dumps(inside))  # sweep chunks cross processes
    assert isinstance(back, Status) and back.record() == inside.record() and back == inside


@pytest.mark.parametrize("backend", ["numpy", "jax"])
def test_a_diverging_run_reports_its_stop_as_a_record(backend):
    """Slotine–Li started 30 rad/s off with max_state = 40: the guard stops it; the result's status and metrics.json's
    `stop` hold the same time and reason, on both backends."""
    arm = ra.TwoLinkArm()
    ctrl = ra.InertiaRelated(arm, Lam=2.5, Kv=10, Gamma=20, phi_hat0=[0, 0])
    res = ra.simulate(ra.Plant(arm, [0.8, 2.3]), ctrl, ra.sinusoid(2), t_final=0.5, dq0=[30.0, -30.0],
                      max_state=40.0, integrator=ra.RK4(1e-3, backend))
    assert isinstance(res.status, Status) and res.status.code == "diverged" and not res.ok
    assert res.status.t == pytest.approx(0.002) and "exceeded 40" in res.status.reason
    m = ra.metrics(res)
    assert m["status"] == str(res.status) and m["stop"] == res.status.record()
    assert np.isclose(m["t_end"], res.t[-1])
