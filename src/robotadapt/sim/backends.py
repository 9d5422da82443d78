"""The backends a fixed-step run is stepped by, as objects (:data:`BACKENDS`): :class:`Numpy` (the Python loop, the
readable reference), :class:`Jax` (`lax.scan` under `jax.jit`) and :class:`C` (that program translated to C,
:mod:`robotadapt.native`). Each says why it cannot run a given run (:meth:`Jax.refuses`: a ConfigError naming
`simulation.backend`, or None), and `simulation.backend = "auto"` chooses by asking them (:func:`choose`).

JAX answers by tracing one step of the run abstractly (`jax.eval_shape`: no compilation). C answers what it knows
without JAX (a compiler, the models' declared traceability): a C program is traced and translated only when it is
first built (a stored one runs without importing JAX), so that is where "auto" learns that JAX cannot trace it or that
the translator lacks one of its primitives (:func:`execute`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from .. import pytree
from ..native.patience import Building, patience
from ..tracing import float64, jax_module
from ..validation import ConfigError
from .driver import Feed, map_tree

T = TypeVar("T")
AUTO_MIN_STEPS = 2000  # "auto" compiles a run of at least this many steps (steps × runs for a batch): below it the
# numpy loop (≈0.3 ms a step on the two-link arm) finishes before a warm program is traced and loaded (≈0.5 s)
_MAX_TRACED = 64


class NotTraceableWarning(UserWarning):
    """Under `backend = "auto"`, a law or model JAX could not trace was stepped with numpy instead (slower, same
    numbers), or a program the C translator lacks a primitive of was compiled with JAX; docs/tutorial.md#traceable says
    what tracing needs and how to check a law."""


@dataclass(frozen=True)
class Run:
    """What the backends are asked about: a fixed step of the run's closed loop (an RK4Step, for a sampled run too: the
    laws' and models' code a compiled program traces), its carry before step 0 and its feed (the driver's); the steps
    the run takes (× runs for a batch); whether its models are traceable as they declare
    (`Model.traceable`: False for compiled code such as Pinocchio's)."""

    step: Any
    carry: Any
    feed: Feed
    steps: int
    traceable: bool = True


class Backend(Protocol):
    """A way to step a fixed-step run: its name and what it refuses."""

    @property
    def name(self) -> str:
        """The `simulation.backend` value that names it."""

    def refuses(self, run: Run) -> ConfigError | None:
        """Why it cannot run `run`, in one line naming `simulation.backend`; None where it can."""


def _untraceable(run: Run) -> ConfigError | None:
    return None if run.traceable else ConfigError(
        "simulation.backend", "the robot's model calls compiled code JAX cannot trace (Pinocchio): use backend = "
        "'numpy', or robot.model = 'tree'")


@dataclass(frozen=True)
class Numpy:
    """The Python loop over steps: the reference, and the engine of plants stepped on the host (MuJoCo's)."""

    name: str = "numpy"

    def refuses(self, run: Run) -> ConfigError | None:
        return None


@dataclass(frozen=True)
class Jax:
    """The steps scanned by one XLA program (float64). Refuses a model declared untraceable, a missing JAX, and a step
    that JAX cannot trace (numpy-only code in a law: docs/tutorial.md#traceable)."""

    name: str = "jax"

    def refuses(self, run: Run) -> ConfigError | None:
        if not run.traceable:
            return _untraceable(run)
        try:
            jax_module()
        except ConfigError as missing:
            return missing
        return _traced(run)


@dataclass(frozen=True)
class C:
    """JAX's program translated to C and built once (:mod:`robotadapt.native`). Refuses where there is no C compiler
    and a model declared untraceable; what tracing and translating find is known when the program is built."""

    name: str = "c"

    def refuses(self, run: Run) -> ConfigError | None:
        from ..native.build import require_compiler

        try:
            require_compiler("simulation.backend")
        except ConfigError as missing:
            return missing
        return _untraceable(run)


BACKENDS: dict[str, Backend] = {"numpy": Numpy(), "jax": Jax(), "c": C()}
_TRACED: dict[Any, ConfigError | None] = {}  # JAX's answer by the probed step's structure


def _traced(run: Run) -> ConfigError | None:
    """Why JAX cannot trace one step of `run` (its arrays abstract, as in the compiled program), or None; kept by the
    step's structure."""
    inputs = map_tree(lambda a: a[0], run.feed(0, 1))
    key = pytree.key((run.step, run.carry, inputs))
    if key not in _TRACED:
        if len(_TRACED) >= _MAX_TRACED:
            _TRACED.pop(next(iter(_TRACED)))
        try:
            _trace(run.step, run.carry, inputs)
            _TRACED[key] = None
        except Exception as exc:  # tracing met code that needs concrete values
            loop = run.step.loop
            name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
            _TRACED[key] = ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                                       f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'")
    return _TRACED[key]


@float64
def _trace(step: Any, carry: Any, inputs: Any) -> None:
    arrays, structure = pytree.flatten(step)
    jax_module().eval_shape(lambda a, c, x: pytree.unflatten(structure, a).compiled()(c, x), arrays, carry, inputs)


def check_backend(backend: Any) -> str:
    """A valid `simulation.backend` name, else a one-line ConfigError naming the field; "c" needs a C compiler."""
    names = ("auto", *BACKENDS)
    if not isinstance(backend, str) or backend not in names:
        raise ConfigError("simulation.backend", f"expected one of {', '.join(names)}; got {backend!r}")
    if backend == "c":
        from ..native.build import require_compiler

        require_compiler("simulation.backend")
    return backend


def choose(asked: str, run: Run) -> Backend:
    """The backend `run` takes: the one `asked` for by name, or its refusal raised. "auto": numpy for a run of fewer
    than `AUTO_MIN_STEPS` steps or with a model declared untraceable; else C where it does not refuse (a compiler is
    present: one native call per chunk, a batch's runs each through the single run's program, no JAX to import once
    the program is stored), JAX where it does not refuse (no compiler), else numpy with a NotTraceableWarning saying
    why."""
    if asked != "auto":
        backend = BACKENDS[asked]
        refusal = backend.refuses(run)
        if refusal is not None:
            raise refusal
        return backend
    if run.steps < AUTO_MIN_STEPS or not run.traceable:
        return BACKENDS["numpy"]
    if BACKENDS["c"].refuses(run) is None:
        return BACKENDS["c"]
    refusal = BACKENDS["jax"].refuses(run)
    if refusal is None:
        return BACKENDS["jax"]
    _fell_back(_stepped_with_numpy(refusal))
    return BACKENDS["numpy"]


def execute(asked: str, run: Run, go: Callable[[str], T]) -> tuple[T, str]:
    """`go(name)` on the backend :func:`choose` takes, and its name. Under "auto", a C program that fails to build
    is stepped with numpy where JAX refuses the run, and compiled with JAX where the translator lacks one of its
    primitives, each with a NotTraceableWarning; a long C program (an n-DOF arm's) is built by a compiler process of
    its own while JAX runs this run (:func:`robotadapt.native.build.patience`); any other failure is raised."""
    backend = choose(asked, run)
    try:
        with patience(asked != "auto"):  # "auto" need not wait for a long C program: JAX runs while gcc builds it
            return go(backend.name), backend.name
    except ConfigError as failed:
        if asked != "auto" or backend.name != "c":
            raise
        instead = _instead_of_c(failed, run)
    return go(instead), instead


def _instead_of_c(failed: ConfigError, run: Run) -> str:
    """The backend a single run takes under "auto" whose C program failed to build (`failed`), else `failed` raised."""
    from ..native.c99 import Unsupported

    refusal = BACKENDS["jax"].refuses(run)
    if refusal is not None:
        _fell_back(_stepped_with_numpy(refusal))
        return "numpy"
    if isinstance(failed, Building):  # the same numbers, compiled by XLA in seconds: no warning
        return "jax"
    if not isinstance(failed, Unsupported):
        raise failed
    _fell_back(f"{failed.reason.split(':')[0]}; compiled with JAX instead (simulation.backend = 'auto')")
    return "jax"


def _stepped_with_numpy(refusal: ConfigError) -> str:
    why = refusal.reason.removesuffix("; use backend = 'numpy'")
    return (f"{why}; stepped with numpy instead (simulation.backend = 'auto'): slower, same numbers — "
            "docs/tutorial.md#traceable")


def _fell_back(why: str) -> None:
    """The warning of "auto", pointed at the caller of simulate (through choose or _instead_of_c, and execute)."""
    warnings.warn(why, NotTraceableWarning, stacklevel=5)
