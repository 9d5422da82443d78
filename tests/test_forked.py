"""Jobs spread over cores by fork (robotadapt.report.forked; issue 45: `robotadapt run`'s figures drawn at once). The
forking path runs in a fresh interpreter (this one may hold JAX, under which nothing forks)."""

import os
import subprocess
import sys
import textwrap

import pytest

from robotadapt.report.forked import groups, spread


@pytest.mark.parametrize("count, cores", [(3, 2), (5, 2), (2, 8), (7, 3), (1, 2), (4, 1), (0, 2)])
def test_groups_cover_the_jobs_in_order_evenly_the_first_the_smallest(count, cores):
    parts = groups(count, cores)
    assert [i for part in parts for i in part] == list(range(count))
    assert len(parts) == max(1, min(cores, count))
    sizes = [len(part) for part in parts]
    assert max(sizes) - min(sizes) <= 1
    assert sizes[0] == min(sizes)


def test_without_a_safe_fork_the_jobs_run_here_in_order(monkeypatch):
    monkeypatch.setitem(sys.modules, "jax", sys.modules.get("jax", object()))
    assert spread([lambda k=k: (k, os.getpid()) for k in range(3)], cores=2) == [(k, os.getpid()) for k in range(3)]


def _fresh(code: str) -> str:
    """What `code` prints in a fresh interpreter (no JAX imported)."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_forked_jobs_give_their_results_in_order_from_other_processes():
    out = _fresh("""
        import os
        from robotadapt.report.forked import spread
        results = spread([lambda k=k: (k, os.getpid()) for k in range(5)], cores=2)
        print([k for k, _ in results], [pid == os.getpid() for _, pid in results], len({pid for _, pid in results}))
    """)
    assert out == "[0, 1, 2, 3, 4] [True, True, False, False, False] 2"


def test_a_forked_jobs_failure_is_raised_here_once_every_process_ended():
    out = _fresh("""
        import os, signal
        from robotadapt.report.forked import spread

        class Odd(Exception):
            def __init__(self, a, b):
                super().__init__(f"{a}/{b}")

        def fail(exc):
            raise exc

        cases = {"value": lambda: fail(ValueError("disk full")), "odd": lambda: fail(Odd(1, 2)),
                 "exit": lambda: os._exit(3), "killed": lambda: os.kill(os.getpid(), signal.SIGKILL)}
        for name, job in cases.items():
            try:
                spread([lambda: "mine", job], cores=2)
            except Exception as exc:
                print(name, type(exc).__name__, exc)
        try:
            spread([lambda: fail(KeyError("first")), lambda: fail(ValueError("second"))], cores=2)
        except Exception as exc:
            print("both", type(exc).__name__, exc)
        try:
            os.waitpid(-1, os.WNOHANG)
            print("a child left")
        except ChildProcessError:
            print("every child reaped")
    """)
    lines = out.splitlines()
    assert lines[0] == "value ValueError disk full"
    assert lines[1] == "odd RuntimeError Odd: 1/2"
    assert lines[2].startswith("exit RuntimeError") and "exit status 3" in lines[2]
    assert lines[3].startswith("killed RuntimeError") and "killed by signal 9" in lines[3]
    assert lines[4] == "both KeyError 'first'"
    assert lines[5] == "every child reaped"


def test_figures_drawn_by_two_processes_equal_those_drawn_by_one(tmp_path):
    out = _fresh(f"""
        import sys
        import robotadapt as ra
        from robotadapt.report.forked import forkable
        res = ra.load("example-6.3.1", ["simulation.t_final=1", "simulation.backend=numpy"]).run()
        assert forkable(), sorted(m for m in sys.modules if m.startswith("jax"))
        one = ra.save_figures(res, {str(tmp_path / "one")!r}, "example-6.3.1")
        two = ra.save_figures(res, {str(tmp_path / "two")!r}, "example-6.3.1", cores=2)
        print([p.name for p in one] == [p.name for p in two], [p.read_bytes() == q.read_bytes() for p, q in zip(one, two)])
    """)
    assert out == "True [True, True, True]"


def test_a_silent_forked_process_is_stopped_and_its_jobs_run_here():
    out = _fresh("""
        import os, time, warnings
        import robotadapt.report.forked as forked
        forked.PATIENCE = 0.5
        parent = os.getpid()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            print(forked.spread([lambda: "mine", lambda: os.getpid() == parent or time.sleep(1000)], cores=2))
        print([str(w.message) for w in caught])
        try:
            os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            print("every child reaped")
    """)
    results, caught, reaped = out.splitlines()
    assert results == "['mine', True]"
    assert "gave no result in 0.5 s and was stopped" in caught
    assert reaped == "every child reaped"
