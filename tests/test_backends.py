"""The backends as objects (robotadapt.sim.backends): what each refuses and why, and what "auto" takes by asking them."""

import dataclasses
import re
import warnings

import numpy as np
import pytest

from robotadapt.controllers import InertiaRelated
from robotadapt.plant import Plant
from robotadapt.robots import TwoLinkArm
from robotadapt.sim import RK4, simulate, simulate_batch
from robotadapt.sim.backends import AUTO_MIN_STEPS, BACKENDS, NotTraceableWarning, Run, choose, execute
from robotadapt.sim.loop import ClosedLoop, RK4Step
from robotadapt.trajectories import sinusoid
from robotadapt.validation import ConfigError

pytest.importorskip("jax", reason="the compiled backends need the [jax] extra (make test installs it)")

ARM, PHI = TwoLinkArm(), np.array([0.8, 2.3])
NOT_TRACEABLE = (r"NumpyOnly on TwoLinkArm cannot be compiled with JAX \(TracerArrayConversionError: [^\n]*\); stepped "
                 r"with numpy instead \(simulation\.backend = 'auto'\): slower, same numbers — "
                 r"docs/tutorial\.md#traceable$")


@dataclasses.dataclass(frozen=True, eq=False)
class NumpyOnly(InertiaRelated):
    """A user's law with a numpy call on its input: JAX cannot trace it."""

    def __call__(self, t, x, q, dq, ref):
        tau, dx = super().__call__(t, x, q, dq, ref)
        return np.asarray(tau) + 0.0, dx


def _law(kind=InertiaRelated):
    return kind(ARM, 2.5, 10.0, 20.0, [0.0, 0.0])


def _run(law, steps, traceable=True):
    loop = ClosedLoop(Plant(ARM, PHI), law, 2, monitored=True)
    step = RK4Step(loop, 1e-3, 1e6)
    z0 = loop.start(np.zeros(4), np.asarray(law.initial_state(np.zeros(2), np.zeros(2)), dtype=float))
    return Run(step, step.start(z0), step.feed(sinusoid(2)), steps, traceable)


@pytest.fixture
def no_compiler(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", str(tmp_path / "nowhere"))


@pytest.fixture
def compiler():
    from robotadapt.native.build import compiler

    if compiler() is None:
        pytest.skip("no C compiler")


def test_each_backend_says_why_it_cannot_run_a_law_jax_cannot_trace(compiler):
    """numpy runs anything; JAX refuses in one line naming the law and what tracing met; C, whose program JAX traces
    only when it is first built (a stored one runs without JAX), learns it there (test below), not when asked."""
    run = _run(_law(NumpyOnly), AUTO_MIN_STEPS)
    refusal = BACKENDS["jax"].refuses(run)
    assert isinstance(refusal, ConfigError) and "\n" not in str(refusal)
    assert re.fullmatch(r"simulation\.backend: NumpyOnly on TwoLinkArm cannot be compiled with JAX "
                        r"\(TracerArrayConversionError: .*\); use backend = 'numpy'", str(refusal))
    assert BACKENDS["numpy"].refuses(run) is None and BACKENDS["c"].refuses(run) is None
    assert all(b.refuses(_run(_law(), AUTO_MIN_STEPS)) is None for b in BACKENDS.values())


def test_both_compiled_backends_refuse_a_model_declared_untraceable(compiler):
    declared = _run(_law(), AUTO_MIN_STEPS, traceable=False)  # Pinocchio's C++
    for name in ("jax", "c"):
        assert str(BACKENDS[name].refuses(declared)).startswith("simulation.backend: the robot's model calls compiled "
                                                                "code JAX cannot trace")


def test_c_refuses_without_a_compiler(no_compiler):
    assert str(BACKENDS["c"].refuses(_run(_law(), AUTO_MIN_STEPS))).startswith("simulation.backend: no C compiler")


@pytest.mark.parametrize("steps, expected", [(AUTO_MIN_STEPS - 1, "numpy"), (AUTO_MIN_STEPS, "c")])
def test_auto_takes_numpy_for_short_runs_and_c_for_long_ones(compiler, steps, expected):
    """A batch too: its runs each go through the single run's C program (driver._compiled, its lanes), faster than JAX's."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert choose("auto", _run(_law(), steps)).name == expected


def test_auto_takes_jax_for_a_long_single_run_without_a_compiler_and_numpy_for_a_declared_untraceable_model(
        no_compiler):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert choose("auto", _run(_law(), AUTO_MIN_STEPS)).name == "jax"
        assert choose("auto", _run(_law(), 10 * AUTO_MIN_STEPS, traceable=False)).name == "numpy"


def test_auto_steps_a_batch_jax_refuses_with_numpy_saying_why():
    with pytest.warns(NotTraceableWarning) as caught:
        res = simulate_batch([Plant(ARM, PHI)] * 2, _law(NumpyOnly), sinusoid(2), t_final=AUTO_MIN_STEPS * 1e-3 / 2,
                             log_every=100)
    assert len(caught) == 1 and re.fullmatch(NOT_TRACEABLE, str(caught[0].message))
    assert all(r.ok for r in res.runs())


def test_auto_steps_a_single_run_whose_c_program_cannot_be_traced_with_numpy_saying_why(compiler):
    with pytest.warns(NotTraceableWarning) as caught:
        res = simulate(Plant(ARM, PHI), _law(NumpyOnly), sinusoid(2), t_final=AUTO_MIN_STEPS * 1e-3, log_every=100)
    assert len(caught) == 1 and re.fullmatch(NOT_TRACEABLE, str(caught[0].message))
    assert res.ok and res.info["backend"] == "numpy"


def test_a_backend_asked_for_by_name_that_refuses_is_a_one_line_error(no_compiler):
    with pytest.raises(ConfigError) as err:
        choose("jax", _run(_law(NumpyOnly), 10))
    assert re.fullmatch(r"simulation\.backend: NumpyOnly on TwoLinkArm cannot be compiled with JAX \(.*\); use "
                        r"backend = 'numpy'", str(err.value))
    with pytest.raises(ConfigError, match=r"^simulation\.backend: no C compiler [^\n]*$"):
        choose("c", _run(_law(), 10))
    with pytest.raises(ConfigError, match=r"^simulation\.backend: NumpyOnly on TwoLinkArm cannot be compiled"):
        simulate(Plant(ARM, PHI), _law(NumpyOnly), sinusoid(2), t_final=0.01, integrator=RK4(1e-3, "jax"))


def test_a_c_program_that_fails_to_build_under_auto(compiler):
    """Where the translator lacks a primitive, JAX runs it (warning); another build failure is raised; a backend asked
    for by name is never replaced."""
    from robotadapt.native.c99 import Unsupported

    def go(failure):
        def run(name):
            if name == "c":
                raise failure
            return name

        return run

    run = _run(_law(), AUTO_MIN_STEPS)
    with pytest.warns(NotTraceableWarning, match=r"^the C translator has no primitive 'eigh'; compiled with JAX instead "
                                                 r"\(simulation\.backend = 'auto'\)$"):
        assert execute("auto", run, go(Unsupported("primitive 'eigh'"))) == ("jax", "jax")
    failed = ConfigError("simulation.backend", "the C compiler cc failed on the translated program: …")
    with pytest.raises(ConfigError) as err:
        execute("auto", run, go(failed))
    assert err.value is failed
    with pytest.raises(Unsupported):
        execute("c", run, go(Unsupported("primitive 'eigh'")))
