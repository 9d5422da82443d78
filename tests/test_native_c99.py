"""The translator from jaxprs to C (issue 28, docs/native.md), primitive by primitive: each small program compiled by
the system's C compiler and run on random inputs equals JAX's own result (to 1e-12: libm's transcendental functions
and XLA's differ in the last bits); a primitive it lacks is one line naming it."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from robotadapt.native import build, c99
from robotadapt.native.build import Compiled, compiler
from robotadapt.native.c99 import PRIMITIVES, Unsupported, translate

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler (set CC or install gcc)")
RNG = np.random.default_rng(28)
A = RNG.normal(size=(3, 4))
B = RNG.normal(size=(4, 2))
V = RNG.normal(size=4)
SPD = (lambda m: m @ m.T + 3 * np.eye(3))(RNG.normal(size=(3, 3)))

CASES = {
    "elementwise": (lambda x, y: (x + y, x - y, x * y, x / (y * y + 1), -x, jnp.maximum(x, y), jnp.minimum(x, y),
                                  jnp.sin(x), jnp.cos(x), jnp.tanh(x), jnp.exp(x), jnp.log1p(x * x), jnp.sqrt(x * x + 1),
                                  jnp.abs(x), jnp.sign(x), jnp.floor(x), x ** 3, jnp.power(jnp.abs(x) + 1, y),
                                  jnp.arctan2(x, y), jnp.fmod(x, y + 3.0), jax.nn.sigmoid(x), x * 2.0 + 1.0), (A, A.T.T)),
    "comparisons and select": (lambda x, y: (jnp.where(x > y, x, y), jnp.where((x >= 0) & (y < 0.5) | (x == y), 1.0, -1.0),
                                             (x != y).astype(float), jnp.clip(x, -0.5, 0.5)), (A, A[::-1])),
    "integers": (lambda k: (k // 3, k % 3, (k * 7 + 2) // -4, jnp.abs(k - 5), k.astype(float) / 2),
                 (np.arange(-6, 6, dtype=np.int64),)),
    "shapes": (lambda x: (x.T, x.reshape(2, 6), x[1:, ::2], x[None, :, 1], jnp.concatenate([x, 2 * x], axis=1),
                          jnp.stack([x[0], x[1]], axis=1), *jnp.split(x, [1], axis=0), jnp.broadcast_to(x[:, :1], (3, 4)),
                          x[::-1], jnp.pad(x, ((1, 0), (0, 2)), constant_values=7.0), jnp.expand_dims(x, 0),
                          jnp.tile(x, (2, 3)), jnp.tile(x[0], 2), jnp.tile(jnp.concatenate([x] * 400), (1, 3))), (A,)),
    "reductions": (lambda x: (x.sum(), x.sum(axis=0), x.max(axis=1), x.min(), x.prod(axis=1), jnp.cumsum(x, axis=1),
                              jnp.cumsum(x[::-1], axis=0), jnp.all(x > -5), jnp.any(x > 2)), (A,)),
    "dot_general": (lambda x, y, v: (x @ y, x @ v, v @ y, jnp.einsum("ij,ij->i", x, x), jnp.outer(v, v),
                                     jnp.einsum("bij,bjk->bik", jnp.stack([x, 2 * x]), jnp.stack([y, y]))), (A, B, V)),
    "iota and dynamic indexing": (lambda x, i: (jnp.arange(5) * i, jax.lax.dynamic_slice(x, (i, 1), (2, 2)),
                                                jax.lax.dynamic_update_slice(x, jnp.ones((1, 2)), (i, 3)),
                                                x.at[i].set(9.0), x.at[:, i].add(1.0), x[i], x[:, i], x[jnp.array([2, 0])],
                                                jax.lax.dynamic_slice(x, (i + 5, 0), (1, 4))), (A, np.int64(1))),
    "linear algebra": (lambda m, b: (jnp.linalg.cholesky(m), jax.scipy.linalg.solve_triangular(jnp.linalg.cholesky(m), b,
                                                                                                lower=True),
                                     jax.scipy.linalg.solve_triangular(m, b, lower=False, trans=1),
                                     jnp.linalg.solve(m, b), jnp.linalg.inv(m),
                                     jax.lax.linalg.triangular_solve(jnp.tril(m), b.T, left_side=False, lower=True),
                                     jax.lax.linalg.triangular_solve(jnp.triu(m), b.T, left_side=False, lower=False,
                                                                     transpose_a=True, unit_diagonal=True)),
                       (SPD, RNG.normal(size=(3, 2)))),
    "empty values": (lambda x, y: (x.sum(axis=1), x.max(axis=1, initial=-1.0), x.min(axis=1, initial=1.0),
                                   jnp.cumsum(x, axis=1), x @ y, jnp.sin(x) * 2.0, x.T @ x),
                     (np.zeros((3, 0)), np.zeros((0, 2)))),
    "nested calls": (lambda x: jax.jit(lambda y: jnp.sin(y) @ y.T)(x) + jax.nn.relu(x[:, :3]), (A,)),
}


def compiled(fn, *args):
    """The native program of `fn(*args)` from the package's one trace-to-C entry, without its outputs' layout."""
    return build.compiled(fn, *args)[0]


@pytest.mark.parametrize("name", CASES)
def test_each_primitive_equals_jax(name):
    fn, args = CASES[name]
    with jax.enable_x64(True):
        expected = jax.tree_util.tree_leaves(fn(*[jnp.asarray(a) for a in args]))
        got = compiled(fn, *args)(*args)
    assert len(got) == len(expected)
    for g, e in zip(got, expected, strict=True):
        e = np.asarray(e)
        assert g.shape == e.shape and g.dtype == e.dtype, name
        np.testing.assert_allclose(g, e, rtol=1e-12, atol=1e-14, err_msg=name)


def test_a_primitive_the_translator_lacks_is_named():
    with pytest.raises(Unsupported, match="no primitive 'eigh'"):
        compiled(lambda m: jnp.linalg.eigh(m)[0], SPD)
    assert {"dot_general", "scatter", "cholesky", "triangular_solve", "cumsum", "select_n", "while", "scan"} <= set(
        PRIMITIVES)


def test_control_flow_equals_jax():
    """while (fori_loop with a traced count), scan (forward and reversed, with outputs) and cond."""
    def fn(x, n):
        a = jax.lax.fori_loop(0, n, lambda i, c: c * 0.5 + jnp.sin(c) + i, x)
        b, ys = jax.lax.scan(lambda c, y: (c + y, (c * y, c - y)), x, jnp.stack([x, 2 * x, 3 * x]))
        c, zs = jax.lax.scan(lambda c, y: (c * 2 + y, c), x[0], x, reverse=True)
        d = jax.lax.cond(x[0] > 0, lambda v: v + 1, lambda v: v * v, x)
        e = jax.lax.switch(n - 2, [lambda v: v, lambda v: -v, lambda v: 2 * v], x)
        return a, b, ys, c, zs, d, e

    x = RNG.normal(size=3)
    with jax.enable_x64(True):
        expected = jax.tree_util.tree_leaves(fn(jnp.asarray(x), 3))
        got = compiled(fn, x, np.int64(3))(x, np.int64(3))
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-12, atol=1e-14)


def test_batched_lu_solves_equal_jax():
    m = np.stack([SPD, 2 * SPD + np.eye(3)])
    b = RNG.normal(size=(2, 3))
    with jax.enable_x64(True):
        fn = lambda m, b: jnp.linalg.solve(m, b[..., None])[..., 0]  # noqa: E731
        np.testing.assert_allclose(compiled(fn, m, b)(m, b)[0], np.asarray(fn(m, b)), rtol=1e-12)


def test_batched_gather_and_scatter_equal_jax():
    """vmap of indexing: gather and scatter with batching dimensions."""
    x, i = RNG.normal(size=(3, 4)), np.array([2, 0, 3])
    fn = jax.vmap(lambda row, k: (row[k], row.at[k].set(-1.0), row.at[k].add(5.0)))
    with jax.enable_x64(True):
        expected = jax.tree_util.tree_leaves(fn(jnp.asarray(x), jnp.asarray(i)))
        got = compiled(fn, x, i)(x, i)
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-12)


def _source(fn, *args):
    with jax.enable_x64(True):
        return translate(jax.make_jaxpr(fn)(*args), "f")


def test_an_equation_computed_twice_is_translated_once():
    """Value numbering: the same primitive on the same values (two calls of one law's regressor in a traced step) is
    written once, element by element; a different operand or parameter is not merged."""
    def twice(x, y):
        a = jnp.tanh(x) @ y
        b = jnp.tanh(x) @ y  # the same again
        c = jnp.tanh(y.T) @ x.T  # other operands
        return a + b, c, jnp.sum(x, axis=0), jnp.sum(x, axis=1)

    text = _source(twice, A, B)
    assert text.count("tanh(") == A.size + B.size  # tanh(x) once, tanh(yᵀ) once
    with jax.enable_x64(True):
        expected = twice(jnp.asarray(A), jnp.asarray(B))
        got = compiled(twice, A, B)(A, B)
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-12, atol=1e-14)


def test_a_program_called_repeatedly_is_one_c_function():
    """A nested program called more than once (an RK4 step's four rates) is one C function called at each site, its
    outputs as JAX's; called once, it is inlined."""
    rate = jax.jit(lambda z, t: jnp.tanh(jnp.outer(z, z) @ z + t) * jnp.cos(z * t) - jnp.sin(z).sum() * z
                   + jnp.stack([z[1:], z[:-1]]).sum() + jnp.cumsum(z) @ jnp.eye(3) + jnp.linalg.norm(z) ** 2
                   + jnp.exp(-z) / (1 + z * z) + jnp.arctan2(z, 1 + t) + jnp.maximum(z, 0) * jnp.minimum(z, t)
                   + jnp.where(z > 0, z, -z) + jnp.floor(z) * jnp.round(t) + jnp.sqrt(1 + z ** 4) + jnp.log1p(z * z)
                   + jnp.sinh(z) + jnp.cosh(z) + jnp.clip(z, -1, 1) * jnp.sign(z) + jnp.max(z) + jnp.min(z)
                   + jnp.prod(z) + jnp.mean(z) + jnp.var(z) + jnp.std(z) + jnp.sort(z) + jnp.abs(z).sum())

    def rk4(z, h):
        k1 = rate(z, 0.0)
        k2 = rate(z + h / 2 * k1, h / 2)
        k3 = rate(z + h / 2 * k2, h / 2)
        k4 = rate(z + h * k3, h)
        return z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    z, h = RNG.normal(size=3), 0.01
    text = _source(rk4, z, h)
    names = re.findall(r"static void (f_f\d+)\(", text)
    assert len(names) == 1 and text.count(f"{names[0]}(") - 1 == 4  # defined once, called four times
    assert "static void f_f" not in _source(lambda z, h: rate(z, h), z, h)
    with jax.enable_x64(True):
        expected = rk4(jnp.asarray(z), h)
    np.testing.assert_allclose(compiled(rk4, z, h)(z, h)[0], np.asarray(expected), rtol=1e-12, atol=1e-14)


def test_a_long_loop_body_is_a_c_function_with_the_same_numbers(monkeypatch):
    """A scan whose body holds at least BODY_FUNCTION_MIN equations calls the body as a C function of its own (gcc's
    register allocation on one long loop body: the Panda's records took 24 s, 5 s so), with the carry and the slices
    as the inlined loop computes them, bit for bit; a shorter body is inlined."""
    from robotadapt.native import control

    def fn(z0, xs):
        def body(z, x):
            z = jnp.tanh(jnp.outer(z, x) @ z) + jnp.sin(z * x.sum())
            return z, (z * 2.0, jnp.cumsum(z))
        return jax.lax.scan(body, z0, xs)

    z0, xs = RNG.normal(size=3), RNG.normal(size=(5, 3))
    inlined = _source(fn, z0, xs)
    assert "static void f_f" not in inlined
    monkeypatch.setattr(control, "BODY_FUNCTION_MIN", 3)
    apart = _source(fn, z0, xs)
    names = re.findall(r"static void (f_f\d+)\(", apart)
    assert len(names) == 1 and apart.count(f"{names[0]}(") == 2  # defined, called in the loop
    got = compiled(fn, z0, xs)(z0, xs)
    monkeypatch.setattr(control, "BODY_FUNCTION_MIN", 10**9)
    want = compiled(fn, z0, xs)(z0, xs)
    with jax.enable_x64(True):
        expected = jax.tree_util.tree_leaves(fn(jnp.asarray(z0), jnp.asarray(xs)))
    for g, w, e in zip(got, want, expected, strict=True):
        np.testing.assert_array_equal(g, w)
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-12, atol=1e-14)


def test_functions_inside_functions_have_their_own_names(monkeypatch):
    """A repeatedly called program that itself calls another repeatedly: two C functions, distinct names, JAX's
    result (the size threshold lowered so that small programs show it)."""
    monkeypatch.setattr(c99, "FUNCTION_MIN", 3)
    inner = jax.jit(lambda z: jnp.tanh(jnp.outer(z, z) @ z) + jnp.cumsum(jnp.sin(z)) * jnp.cos(z).sum())
    outer = jax.jit(lambda z: inner(z) + 2 * inner(z[::-1]) + jnp.exp(-z * z))

    def fn(z):
        return outer(z) - outer(2 * z)

    z = RNG.normal(size=3)
    names = re.findall(r"static void (f_f\d+)\(", _source(fn, z))
    assert len(names) == 2 and len(set(names)) == 2
    with jax.enable_x64(True):
        expected = fn(jnp.asarray(z))
    np.testing.assert_allclose(compiled(fn, z)(z)[0], np.asarray(expected), rtol=1e-12, atol=1e-12)


def test_small_values_are_held_as_elements_and_their_zeros_fold():
    """A small float64 value is held element by element: a product with a 0/1 mask and a dense matrix times a vector
    whose structural zeros the translator is told of write no multiply by a zero, and the program still equals JAX
    (on inputs with those zeros); a large value stays a loop nest."""
    mask = np.tril(np.ones((4, 4)))
    gain = np.diag([1.0, 2.0, 3.0, 4.0])

    def fn(x, y, g):
        return (x[:, None] * y[None, :] * mask).sum(axis=1), g @ x, jnp.sin(jnp.outer(jnp.concatenate([x] * 300), y)).sum()

    x, y = RNG.normal(size=(2, 4))
    with jax.enable_x64(True):
        closed = jax.make_jaxpr(fn)(x, y, gain)
        expected = fn(jnp.asarray(x), jnp.asarray(y), jnp.asarray(gain))
    zeros = [None, None, gain == 0]
    text = translate(closed, "f", zeros=zeros)
    body = text[text.index("static void f("):]
    assert set(re.findall(r"\bin2\[(\d+)\]", body)) == {"0", "5", "10", "15"}  # only Γ's diagonal is read
    products = {(int(i), int(j)) for i, j in re.findall(r"in0\[(\d)\]\)? \* \(?in1\[(\d)\]", body)}
    assert products == {(i, j) for i in range(4) for j in range(i + 1)}  # the mask's upper triangle is gone
    assert "for (int" in body  # the 1200×4 sines: a loop
    got = Compiled.translated(closed, "held", zeros=zeros)(x, y, gain)
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_allclose(g, np.asarray(e), rtol=1e-12, atol=1e-14)


def test_unread_elements_are_not_declared():
    """An element whose only reader folded away (a factor of a product with zero) is not declared: C compilers warn of
    unused variables (the export is built with -Wall -Werror)."""
    def fn(x):
        return jnp.sin(x) * jnp.array([0.0, 1.0, 0.0])

    with jax.enable_x64(True):
        text = translate(jax.make_jaxpr(fn)(V[:3]), "f")
    assert text.count("sin(") == 1


def test_constants_are_computed_at_translation_empty_ones_included():
    """An equation on constants only (an identity built from iota, a product of empty arrays: the passivity law's
    zero-width filter) is computed when translated: the identity folds away, and the program equals JAX."""
    def fn(x):
        empty = jnp.zeros((0, 2)) * x[0]
        return jnp.eye(2) @ x + jnp.zeros(0) @ empty

    x = RNG.normal(size=2)
    with jax.enable_x64(True):
        text = translate(jax.make_jaxpr(fn)(x), "f")
        expected = fn(jnp.asarray(x))
    assert " * " not in text  # eye(2) @ x is x
    np.testing.assert_allclose(compiled(fn, x)(x)[0], np.asarray(expected), rtol=1e-12, atol=1e-14)
