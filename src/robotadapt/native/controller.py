"""A controller's tick as a C library with a fixed API, for a robot's real-time loop (docs/native.md).

Given the two traced programs of a controller — `init(q, q̇) -> state` and `tick(state, [k, t, q, q̇]) -> (τ, state')`
(:mod:`robotadapt.realtime` builds them from a scenario) — :func:`export` writes `PREFIX.h` and `PREFIX.c` with

    int    PREFIX_n(void);                       /* joints */
    size_t PREFIX_state_size(void);              /* doubles of state: the tick counter k, then the controller's */
    void   PREFIX_reset(double *state, const double *q, const double *dq);
    void   PREFIX_step(double *state, double t, const double *q, const double *dq, double *tau);

the semantics of `RealtimeController.reset` / `.step`: reset starts at the measured state with k = 0, each step returns
τ_k at (t, q, q̇) and advances the state to tick k + 1 in place. No allocation, no global state but the constant tables
(and the static scratch arrays of large temporaries, :data:`robotadapt.native.emitter.STACK_LIMIT`: one caller at a time),
libm only. :func:`harness` is an example program: it reads lines `t q1…qn dq1…dqn` and prints τ per line.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from ..validation import ConfigError
from .c99 import translate
from .lowering import equations

PREFIX = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,30}$")


@dataclass(frozen=True)
class Export:
    """The files of one exported controller: `header` (PREFIX.h), `source` (PREFIX.c), `harness` (PREFIX_harness.c),
    and `n`, `state_size`, `prefix`, `primitives` (equations of the tick's program, nested calls counted)."""

    prefix: str
    n: int
    state_size: int
    header: str
    source: str
    harness: str
    primitives: int

    @property
    def standalone(self) -> str:
        """PREFIX.c with PREFIX.h pasted in place of its #include: one translation unit for a shared library."""
        return self.source.replace(f'#include "{self.prefix}.h"\n', self.header)


def check_prefix(prefix: str) -> str:
    if not isinstance(prefix, str) or not PREFIX.match(prefix):
        raise ConfigError("--prefix", f"expected a C identifier of at most 31 characters (letters, digits, _), got "
                          f"{prefix!r}")
    return prefix


def export(tick: Any, init: Any, n: int, prefix: str = "ra", what: str = "") -> Export:
    """The C export of a controller from its ClosedJaxprs `tick` (state (m,), inputs (2 + 2n,)) -> (τ (n,), state (m,))
    and `init` (q (n,), q̇ (n,)) -> state (m,); `what` describes it in the files' first comment."""
    prefix = check_prefix(prefix)
    m = int(tick.jaxpr.invars[0].aval.shape[0])
    size = m + 1
    guard = f"{prefix.upper()}_H"
    header = f"""/* {prefix}.h: {what or 'a controller'}, exported by robotadapt (docs/native.md).
 * State: {size} doubles (the tick counter k, then the controller's state); joints: {n}. No allocation, libm only.
 * Build: cc -O2 -c {prefix}.c   (link with -lm)                                                              */
#ifndef {guard}
#define {guard}
#include <stddef.h>
#ifdef __cplusplus
extern "C" {{
#endif
int {prefix}_n(void);                                             /* joints: {n} */
size_t {prefix}_state_size(void);                                 /* doubles of state: {size} */
void {prefix}_reset(double *state, const double *q, const double *dq);   /* start at the measured q, dq; k = 0 */
void {prefix}_step(double *state, double t, const double *q, const double *dq, double *tau);  /* tau_k; k += 1 */
#ifdef __cplusplus
}}
#endif
#endif
"""
    body = [f"/* {prefix}.c: {what or 'a controller'}, exported by robotadapt: do not edit (re-export instead). */",
            f'#include "{prefix}.h"', "#include <math.h>", "#include <stdint.h>", "#include <string.h>", "",
            translate(tick, f"{prefix}_tick_impl"), translate(init, f"{prefix}_init_impl"),
            f"int {prefix}_n(void) {{ return {n}; }}",
            f"size_t {prefix}_state_size(void) {{ return {size}; }}",
            f"void {prefix}_reset(double *state, const double *q, const double *dq) {{",
            "    state[0] = 0.0;", f"    {prefix}_init_impl(q, dq, state + 1);", "}",
            f"void {prefix}_step(double *state, double t, const double *q, const double *dq, double *tau) {{",
            f"    double in[{2 + 2 * n}];", "    in[0] = state[0];", "    in[1] = t;",
            f"    memcpy(in + 2, q, {n} * sizeof(double));", f"    memcpy(in + {2 + n}, dq, {n} * sizeof(double));",
            f"    {prefix}_tick_impl(state + 1, in, tau, state + 1);  /* the new state is written last */",
            "    state[0] += 1.0;", "}", ""]
    return Export(prefix, n, size, header, "\n".join(body), harness(prefix, n),
                  equations(tick.jaxpr) + equations(init.jaxpr))


def harness(prefix: str, n: int) -> str:
    """An example program around the export: reset at the first line's (q, q̇), then one step per line."""
    return f"""/* {prefix}_harness.c: reads lines "t q1..q{n} dq1..dq{n}" from stdin, prints tau_k per line.
 * Build: cc -O2 -o {prefix}_harness {prefix}_harness.c {prefix}.c -lm                                  */
#include <stdio.h>
#include <stdlib.h>
#include "{prefix}.h"

int main(void) {{
    int n = {prefix}_n();
    double *state = malloc({prefix}_state_size() * sizeof(double));  /* once, before the loop */
    double t, q[{n}], dq[{n}], tau[{n}];
    int first = 1;
    while (scanf("%lf", &t) == 1) {{
        for (int i = 0; i < n; i++) if (scanf("%lf", &q[i]) != 1) return 1;
        for (int i = 0; i < n; i++) if (scanf("%lf", &dq[i]) != 1) return 1;
        if (first) {{ {prefix}_reset(state, q, dq); first = 0; }}
        {prefix}_step(state, t, q, dq, tau);  /* in a robot's callback: this call only */
        for (int i = 0; i < n; i++) printf(i + 1 < n ? "%.17g " : "%.17g\\n", tau[i]);
    }}
    free(state);
    return 0;
}}
"""
