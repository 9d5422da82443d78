"""A law registers itself, in its own class body: its scenario kind, its other names, how tuning varies it and (a
control law) its entries in the comparison's lineup (docs/architecture.md#a-law-registers-itself)::

    @dataclass(frozen=True, eq=False)
    class DeadZone(Law):
        kind = "dead_zone"                  # [controller] kind = "dead_zone"; ra.DeadZone
        tuned = ("Lam", "Kv", "Gamma")      # the gains `robotadapt compare --fair` may vary
        family = "6"                        # shares Λ, K_v, Γ with the chapter-6 laws in the comparison
        lineup = (Contender("dead_zone", "Slotine–Li + dead zone", "Peterson & Narendra", "Example 6.3.1",
                            {"kind": "dead_zone", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0, "delta": 0.2}, rank=110),)

A class registers when its own body sets `kind`, into the table of its `registry`: "controller" (the laws,
:class:`~robotadapt.controllers.base.Law`) or "law" (the update laws of the passivity class,
:mod:`robotadapt.controllers.adaptation`). A subclass of a registered law does not, unless it names a kind of its own;
its `aliases` and `lineup` are then its own too (none unless it sets them), its `tuned`, `family` and `powers` its
parent's unless it sets them. A kind or alias taken by another class, or not a plain name, is a TypeError where the
class is defined. :func:`registered` imports every module of `robotadapt.controllers` first, so that every packaged
law is there, and holds any law a user's module registered since; the scenario kinds
(:mod:`robotadapt.studies.scenarios.build`), the front door's names (`ra.InertiaRelated`), the comparison's lineup and
what it tunes (:mod:`robotadapt.studies.compare`) are all read from it. A law named `kind = "module:Class"` from a
scenario needs none of this.
"""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

#: registry → kind → the class that registered it; registry → other name → kind
_KINDS: dict[str, dict[str, type[Registered]]] = {"controller": {}, "law": {}}
_ALIASES: dict[str, dict[str, str]] = {"controller": {}, "law": {}}
_DISCOVERED = [False]


@dataclass(frozen=True, eq=False)
class OfTruth:
    """A lineup value derived from the true φ: `factor`·φ, or `factor`·‖φ‖ with `norm` (the comparison evaluates it
    on the scenario's plant; the law itself never sees the truth)."""

    factor: float
    norm: bool = False

    def value(self, phi: np.ndarray) -> Any:
        return self.factor * float(np.linalg.norm(phi)) if self.norm else (self.factor * phi).tolist()


class Contender(NamedTuple):
    """An entry of the comparison's lineup (:mod:`robotadapt.studies.compare`): a law with the book's gains for the
    book's two-link arm, which the comparison carries over to the scenario's arm."""

    name: str  # the entry's name (`robotadapt compare --controllers NAME`)
    label: str
    reference: str  # the book's equations
    gains: str  # where the gains come from
    section: dict[str, Any]  # the scenario's [controller] table, its kind the law's (OfTruth values from the true φ)
    rank: float = math.inf  # its place in the lineup (the package's: 10, 20, ...; ties by name)
    book_kv: str = ""  # where it is from, when this entry's K_v is its family's k_v,book (the denominator of the scale)


class Registered:
    """What a law declares about itself in its class body (module docstring); every declaration has a default, so a
    class that sets none of them is a law as before, named from a scenario by `"module:Class"`."""

    #: the table the class registers in ("controller", "law") and what its constructor takes first there
    registry: ClassVar[str] = "controller"
    first: ClassVar[str | None] = "model"
    #: its scenario kind (None: not registered) and other names for it
    kind: ClassVar[str | None] = None
    aliases: ClassVar[tuple[str, ...]] = ()
    #: the gains a fair comparison tunes where the law has them (`robotadapt.studies.gain_space.locate` refuses those
    #: the law derives other constants from that it cannot recompute from a traced gain)
    tuned: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        if "kind" in vars(cls) and _declared(cls):
            for name in ("aliases", "lineup"):  # a kind's other names and lineup entries are its own, not its parent's
                if name not in vars(cls) and hasattr(cls, name):
                    setattr(cls, name, ())
            register(cls)  # first: a class refused here is not registered anywhere else either
        super().__init_subclass__(**kwargs)


def _declared(cls: type) -> bool:
    """Whether `cls` sets a kind to register: its own `kind`, not None and not a dataclass field of that name."""
    annotation = inspect.get_annotations(cls).get("kind")
    return vars(cls)["kind"] is not None and (annotation is None or "ClassVar" in str(annotation))


def _same(a: type, b: type) -> bool:
    """The same class, or its definition run again (a module reloaded, a notebook cell run twice)."""
    return a is b or (a.__module__, a.__qualname__) == (b.__module__, b.__qualname__)


def register(cls: type[Registered]) -> None:
    """Register `cls` under its `kind` and `aliases` in its `registry` (done by defining the class; for a class
    unregistered before). A kind is a plain name (no ":", which names a user's class), taken once."""
    kind, table = cls.kind, _KINDS.get(cls.registry)
    if table is None:
        raise TypeError(f"{cls.__name__}.registry: expected one of {', '.join(_KINDS)}, got {cls.registry!r}")
    names = (kind, *cls.aliases)
    for name in names:
        if not isinstance(name, str) or not name.isidentifier():
            raise TypeError(f"{cls.__name__}.kind: expected a name such as 'dead_zone' (letters, digits, _), got "
                            f"{name!r}")
        owner = table.get(_ALIASES[cls.registry].get(name, name))
        if owner is not None and not _same(owner, cls):
            raise TypeError(f"{cls.__name__}: the {cls.registry} kind {name!r} is {owner.__module__}."
                            f"{owner.__qualname__}'s; choose another name")
    entries = {c.name: law for law in _KINDS["controller"].values() if not _same(law, cls)
               for c in getattr(law, "lineup", ())}
    for c in getattr(cls, "lineup", ()):
        if not isinstance(c, Contender) or c.section.get("kind") not in names:
            raise TypeError(f"{cls.__name__}.lineup: expected Contender(...) entries whose section has kind = "
                            f"{kind!r}, got {c!r}")
        if c.name in entries:
            raise TypeError(f"{cls.__name__}.lineup: the entry {c.name!r} is {entries[c.name].__qualname__}'s")
    for old in [k for k, v in table.items() if _same(v, cls)]:
        unregister(table[old])
    table[str(kind)] = cls
    _ALIASES[cls.registry].update(dict.fromkeys(cls.aliases, str(kind)))


def unregister(cls: type[Registered]) -> None:
    """Take `cls` (its kind and aliases) out of its registry; nothing if it is not there."""
    table = _KINDS.get(cls.registry, {})
    for kind in [k for k, v in table.items() if v is cls]:
        del table[kind]
        aliases = _ALIASES[cls.registry]
        for alias in [a for a, k in aliases.items() if k == kind]:
            del aliases[alias]


def discover() -> None:
    """Import every module of `robotadapt.controllers` (once per process): each packaged law registers as its module
    runs. The modules import numpy only (no JAX, scipy or matplotlib)."""
    if _DISCOVERED[0]:
        return
    package = importlib.import_module(__name__.rpartition(".")[0])
    for module in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"{package.__name__}.{module.name}")
    _DISCOVERED[0] = True


def _order(item: tuple[str, type[Registered]]) -> tuple[float, str]:
    """A registry's order: by the rank of a law's first lineup entry (the lineup's order), then by kind."""
    kind, cls = item
    return min((c.rank for c in getattr(cls, "lineup", ())), default=math.inf), kind


def registered(registry: str = "controller") -> dict[str, Any]:
    """kind → class of every law registered in `registry` ("controller" or "law"), the packaged ones and any a user's
    module registered, in the lineup's order (then by kind)."""
    discover()
    return dict(sorted(_KINDS[registry].items(), key=_order))


def aliases(registry: str = "controller") -> dict[str, str]:
    """Other name → kind, of the laws registered in `registry` (`inertia_related` → `slotine_li`)."""
    discover()
    return dict(_ALIASES[registry])


def by_name() -> dict[str, Any]:
    """Class name → class of every registered law and update law (the front door's `ra.InertiaRelated`); where two
    share a name, the package's."""
    out: dict[str, Any] = {}
    for cls in sorted((c for table in ("controller", "law") for c in registered(table).values()),
                      key=lambda c: not c.__module__.startswith("robotadapt.")):
        out.setdefault(cls.__name__, cls)
    return out
