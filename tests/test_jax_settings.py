"""Running the project's programs leaves the user's JAX as it was (issue 23): float64 is scoped to the project's own
programs (`robotadapt.sim.compiled.float64`), and the results are float64 all the same."""

from __future__ import annotations

import subprocess
import sys

CODE = """
import jax, numpy as np
import robotadapt as ra
assert not jax.config.jax_enable_x64
numpy_run = ra.load("example-6.3.1", ["simulation.t_final=0.3", "simulation.backend='numpy'"]).run()
res = ra.load("example-6.3.1", ["simulation.t_final=0.3", "simulation.backend='jax'"]).run()
assert np.abs(res.q - numpy_run.q).max() < 1e-12, np.abs(res.q - numpy_run.q).max()
setup = ra.load("example-6.3.1").setup
batch = ra.simulate_batch(setup.plant, setup.controller, setup.trajectory, t_final=0.3, q0=np.zeros((2, 2)),
                          integrator=ra.Sampled(0.002, backend="jax"))
assert batch.ok.all() and batch.z.dtype == np.float64
assert not jax.config.jax_enable_x64
assert jax.numpy.ones(1).dtype == np.float32  # the user's JAX: float32, as it was
print("ok")
"""


def test_a_run_leaves_the_users_jax_settings_as_they_were():
    p = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and p.stdout.strip().endswith("ok"), p.stderr[-2000:]
