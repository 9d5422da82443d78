"""Values JAX understands: the package's models, laws, plants, trajectories and transitions are frozen dataclasses
deriving from :class:`Module`, pytrees whose leaves are their float arrays and whose structure (integers, flags,
strings, Python numbers, integer tables, a model's dict of constants) is static.

This is what Equinox's `filter_jit` does, written once for the package and kept free of JAX: a warm process runs its
C programs without importing JAX, so the flattening is ours (:func:`flatten`, :func:`unflatten`), and the same
functions are registered with JAX (`jax.tree_util.register_pytree_with_keys`) once JAX is loaded — by the package's
first compiled program (:func:`register`, from :func:`robotadapt.tracing.jax_module`), or as each class is defined
where the user imported JAX first (a user who imports JAX later calls :func:`register`); `import robotadapt` itself
imports no JAX. Then `jax.tree_util.tree_leaves(law)` gives
the law's arrays, `jax.tree_util.tree_map` and `jax.vmap` work on it, and two objects with the same structure share
one compiled program: a new gain value (an array) never recompiles.

Rules (per instance, at flattening):

- a leaf is a float numpy array or a JAX array (a traced one inside a program): gains, true parameters, tables;
- a dataclass (a :class:`Module`, or a user's), a tuple, list or NamedTuple is walked, field by field (the fields of
  `dataclasses.fields`, not the attributes); a dict is a constant (by value);
- anything else is part of the structure, compared by value (arrays by their bytes; an unhashable object by
  identity);
- a field declared with :func:`host` (a sensor's seed) is read on the host only: it travels with the structure but is
  not compared, so runs that differ in it share a program;
- a constant derived from the fields (Γ⁻¹, a Lyapunov pair) is a :class:`derived` property: computed once, at the
  first flattening at the latest, and flattened with the fields (the host computes it; a program takes it as a leaf),
  so a run never changes an object's key; :func:`replace` drops it, and the new object computes it again from its
  (possibly traced) leaves. A plain `cached_property` (a host-side engine) is not part of the tree.

Unflattening never calls `__init__`: validation ran once, at construction, and traced leaves could not pass it.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from dataclasses import Field, field, fields, is_dataclass
from functools import cache, cached_property
from typing import Any, ClassVar

import numpy as np

Array = Any
_CLASSES: list[type] = []  # every Module subclass, registered with JAX once it is loaded
_REGISTERED: set[type] = set()
_JAX = [False]  # JAX is loaded and the classes so far registered


class derived(cached_property[Any]):  # noqa: N801 (a decorator, as cached_property)
    """A cached property that is part of its object's tree (module docstring): a constant derived from the fields."""


class Module:
    """Base of the package's frozen dataclasses that programs take as arguments (module docstring). A subclass is a
    pytree by being one; a user's law deriving from :class:`~robotadapt.controllers.base.Law` is one too."""

    #: the fields whose math broadcasts over a leading run axis: runs that differ in them (and in nothing else) step as
    #: one vectorized loop (robotadapt.sim.batch.stack), each declared by its class and checked in tests/test_batch.py
    per_run: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        _CLASSES.append(cls)
        if _JAX[0] or "jax" in sys.modules:  # JAX is loaded: a class defined later is registered at once
            register()


def host(default: Any = None) -> Any:
    """A dataclass field read on the host only (never inside a compiled program): not part of a program's key."""
    return field(default=default, metadata={"host": True})


class Static:
    """A value of the structure, hashed and compared by value (arrays by bytes, unhashable objects by identity); a
    :func:`host` field's value compares equal to any other."""

    __slots__ = ("value", "key")

    def __init__(self, value: Any, compared: bool = True) -> None:
        self.value = value
        self.key = _constant(value) if compared else None

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Static) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __repr__(self) -> str:
        return f"Static({self.key!r})"


def _constant(obj: Any) -> Any:
    """`obj` as a hashable constant: arrays by their bytes, containers item by item, an unhashable object by identity."""
    if isinstance(obj, np.ndarray):
        return ("const", obj.shape, obj.dtype.str, obj.tobytes())
    if isinstance(obj, tuple | list):
        return (type(obj), tuple(_constant(v) for v in obj))
    if isinstance(obj, dict):
        return (dict, tuple((k, _constant(v)) for k, v in sorted(obj.items())))
    if _walked(obj):
        return (type(obj), tuple((f.name, _constant(getattr(obj, f.name))) for f in _fields(type(obj))))
    try:
        hash(obj)
    except TypeError:
        return ("id", id(obj))
    return obj


def is_leaf(obj: Any) -> bool:
    """A float numpy array, or a JAX array (concrete or traced)."""
    if isinstance(obj, np.ndarray):
        return obj.dtype.kind == "f"
    return "jax" in sys.modules and isinstance(obj, sys.modules["jax"].Array)


def _fields(cls: type) -> tuple[Field[Any], ...]:
    return fields(cls)


@cache
def _derived(cls: Any) -> tuple[str, ...]:
    """The names of the class's :class:`derived` properties, in definition order along the MRO."""
    names: dict[str, None] = {}
    for klass in reversed(cls.__mro__):
        names.update((k, None) for k, v in vars(klass).items() if isinstance(v, derived))
    return tuple(names)


def _walked(obj: Any) -> bool:
    """A dataclass instance: flattened field by field."""
    return is_dataclass(obj) and not isinstance(obj, type)


def flatten(obj: Any, with_derived: bool = True) -> tuple[list[Array], Any]:
    """(the leaves of `obj` in order, its structure): the structure is hashable, equal for objects that differ only in
    their leaves' values (and host fields), and rebuilds the object with :func:`unflatten`. `with_derived=False`: the
    fields only (what two builds of a law from different gains share)."""
    leaves: list[Array] = []
    return leaves, _structure(obj, leaves, with_derived)


def _structure(obj: Any, leaves: list[Array], with_derived: bool) -> Any:
    if is_leaf(obj):
        leaves.append(obj)
        return ("leaf", tuple(obj.shape))
    if _walked(obj):
        kind: Any = type(obj)
        parts = [(f.name, Static(getattr(obj, f.name), compared=False) if f.metadata.get("host")
                  else _structure(getattr(obj, f.name), leaves, with_derived)) for f in _fields(kind)]
        if with_derived:
            parts += [(name, _structure(getattr(obj, name), leaves, True)) for name in _derived(kind)]
        return (kind, tuple(parts))
    if isinstance(obj, tuple | list):
        return (type(obj), tuple(_structure(v, leaves, with_derived) for v in obj))
    return Static(obj)


def unflatten(structure: Any, leaves: Iterable[Array]) -> Any:
    """The object of `structure` (from :func:`flatten`) with `leaves` in its leaves' places; no `__init__` is run."""
    return _build(structure, iter(leaves))


def _build(structure: Any, leaves: Iterator[Array]) -> Any:
    if isinstance(structure, Static):
        return structure.value
    kind, parts = structure
    if kind == "leaf":
        return next(leaves)
    if isinstance(kind, type) and is_dataclass(kind):
        new = object.__new__(kind)
        for name, part in parts:
            object.__setattr__(new, name, _build(part, leaves))
        return new
    items = [_build(p, leaves) for p in parts]
    return kind(*items) if hasattr(kind, "_fields") else kind(items)  # a NamedTuple takes its fields


def leaves(obj: Any) -> list[Array]:
    """The leaves of `obj`, in :func:`flatten`'s order."""
    return flatten(obj)[0]


def key(obj: Any) -> Any:
    """The structure of `obj`: what names its compiled program (objects with equal keys share one)."""
    return flatten(obj)[1]


def replace(obj: Any, path: tuple[str, ...], value: Any) -> Any:
    """`obj` with the field at `path` (e.g. ("controller", "law", "F_p")) set to `value` (Equinox's `tree_at`): copies
    along the path without `__init__` (so `value` may be traced) and without derived or cached properties (they may
    derive from the old value); the original is untouched."""
    new = object.__new__(type(obj))
    for f in _fields(type(obj)):
        object.__setattr__(new, f.name, getattr(obj, f.name))
    head = getattr(obj, path[0])
    object.__setattr__(new, path[0], value if len(path) == 1 else replace(head, path[1:], value))
    return new


def register() -> None:
    """Register every Module subclass with JAX (idempotent); classes defined later register themselves."""
    _JAX[0] = True
    for cls in list(_CLASSES):
        _register(cls)


def _register(cls: type) -> None:
    if cls in _REGISTERED:
        return
    import jax

    def keyed(obj: Any) -> tuple[list[tuple[Any, Array]], Any]:
        found, structure = flatten(obj)
        return [(jax.tree_util.SequenceKey(i), a) for i, a in enumerate(found)], structure

    jax.tree_util.register_pytree_with_keys(cls, keyed, unflatten, flatten)
    _REGISTERED.add(cls)
