"""Equal numbers (issue 41, item 7): capture every packaged scenario's numbers from one source tree, compare two captures.

`capture OUT_DIR [--src SRC] [--only PATTERN] [--jobs N]` runs, for every packaged scenario S of SRC (the TOML files in
SRC/robotadapt/studies/scenarios/; default this checkout's src), these variants, each into OUT_DIR/<variant>/:

* `S@packaged`: the scenario as it ships (backend "auto") with t_final cut to at most 2 s, the 2000 steps at 1 kHz
  from which "auto" compiles;
* `S@rk4-B` and `S@sampled-B` for B in numpy, jax, c: continuous RK4 (control_period removed) and sampled-data (the
  scenario's own control_period, else the whole multiple of its dt nearest 2 ms), with t_final cut to 1 s (one- and
  two-link arms) or 0.5 s (n-DOF arms).

Each variant folder gets result.npz, metrics.json and scenario.toml as `robotadapt run` writes them (no figures, no
[study] runs) and status.json: "ran" (diverged runs included: their status is in metrics.json), "refused" (a
ConfigError, with its message), "error" (any other exception) or "crashed" (the process died or timed out). One worker
process per scenario imports robotadapt with PYTHONPATH=SRC first (its `__file__` is checked and logged in
OUT_DIR/capture.log) and ROBOTADAPT_CACHE=OUT_DIR/.cache, so compiled programs of different trees never mix. A digest
of SRC's .py and .toml files is logged before and after: a tree edited during the capture fails it (snapshot a tree
that is being worked on, `cp -r`, and capture the copy).

`compare A_DIR B_DIR` compares every variant of two captures: every leaf of metrics.json except the wall-clock key
`wall_time_s` (the only timing-like key the code writes) and every array of result.npz. Numbers are compared by

    rel = |a − b| / max(|a|, |b|, 1e-6·S, 1e-300),

S the largest magnitude of that key or array in either tree: values near zero relative to their own array's scale are
compared absolutely against 1e-6·S; NaN equals NaN; strings, booleans and None must be identical (else rel = inf). A
variant is "equal" (max rel ≤ 1e-12), "small" (≤ 1e-9), "large", "missing" (a key, an array or the variant absent on
one side, a shape that differs, or a status that differs) or "refused" (refused on both sides). Exits 1 if anything is
large or missing.
"""

from __future__ import annotations

import argparse
import fnmatch
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TextIO

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DEFAULT_SRC = Path(__file__).resolve().parents[1] / "src"
BACKENDS = ("numpy", "jax", "c")
PACKAGED_T_FINAL = 2.0  # s, at most
BOOK_ARMS = ("one_link", "two_link", "polar")  # robot kinds cut to 1 s; the n-DOF arms to 0.5 s
CONTROL_PERIOD = 2e-3  # about the control period of the sampled-data variant of a continuous scenario
WORKER_TIMEOUT = 1800.0  # s, one scenario's variants
WALL_CLOCK = ("wall_time_s",)
EQUAL, SMALL, FLOOR = 1e-12, 1e-9, 1e-6
Job = tuple[str, str, list[str]]  # variant, scenario, overrides


def _toml(value: Any) -> str:
    """A TOML scalar, or an inline table of scalars."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    if isinstance(value, bool):
        return "true" if value else "false"
    return json.dumps(value) if isinstance(value, str) else repr(value)


def variants(name: str, data: dict[str, Any]) -> list[Job]:
    """The packaged run of scenario `name` (its parsed TOML `data`) and its continuous and sampled runs per backend."""
    sim = data["simulation"]
    t_final = 1.0 if data["robot"]["kind"] in BOOK_ARMS else 0.5
    continuous = {k: v for k, v in sim.items() if k not in ("control_period", "discretization")}
    dt = sim.get("dt", 1e-3)
    sampled = {**sim, "control_period": sim.get("control_period", max(1, round(CONTROL_PERIOD / dt)) * dt)}
    jobs: list[Job] = [(f"{name}@packaged", name, [f"simulation.t_final={min(sim['t_final'], PACKAGED_T_FINAL)!r}"])]
    for mode, table in (("rk4", continuous), ("sampled", sampled)):
        for backend in BACKENDS:
            section = {**table, "t_final": t_final, "backend": backend}
            jobs.append((f"{name}@{mode}-{backend}", name, [f"simulation={_toml(section)}"]))
    return jobs


def worker(out: Path, jobs: list[Job]) -> None:
    """Run `jobs` in this process (robotadapt from PYTHONPATH); write each variant's files and status.json."""
    import robotadapt as ra

    print(f"robotadapt from {ra.__file__}", flush=True)
    for variant, scenario, overrides in jobs:
        folder = out / variant
        folder.mkdir(parents=True)
        record: dict[str, Any] = {"scenario": scenario, "overrides": overrides}
        start = time.perf_counter()
        try:
            loaded = ra.load(scenario, overrides)
            result = loaded.run()
            ra.save_result(result, folder, loaded.text, model=loaded.setup.controller.model)
            record.update(status="ran", run_status=str(result.status), backend=result.info.get("backend"))
        except Exception as exc:  # every failure is recorded, and the next variant runs
            refused = type(exc).__name__ == "ConfigError"
            record.update(status="refused" if refused else "error", message=str(exc))
            if not refused:
                record["traceback"] = traceback.format_exc()
        record["seconds"] = round(time.perf_counter() - start, 2)
        (folder / "status.json").write_text(json.dumps(record, indent=2))
        print(f"{variant}: {record['status']} {record.get('run_status', record.get('message', ''))} "
              f"({record.get('backend')}, {record['seconds']} s)", flush=True)


def _environment(src: Path, out: Path) -> dict[str, str]:
    """This environment with `src` first on PYTHONPATH and the compile cache under `out`."""
    env = dict(os.environ, ROBOTADAPT_CACHE=str(out / ".cache"))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(src), env.get("PYTHONPATH", "")) if p)
    return env


def _run_scenario(jobs: list[Job], out: Path, env: dict[str, str], log: TextIO, lock: threading.Lock) -> None:
    """Run one scenario's variants in a worker; a variant that kills the worker is recorded as crashed, the rest rerun."""
    remaining = list(jobs)
    while remaining:
        for variant, _, _ in remaining:
            shutil.rmtree(out / variant, ignore_errors=True)
        command = [sys.executable, __file__, "_worker", str(out), json.dumps(remaining)]
        try:
            proc = subprocess.run(command, env=env, cwd=out, capture_output=True, text=True, timeout=WORKER_TIMEOUT)
            code, text, why = proc.returncode, proc.stdout + proc.stderr, proc.stderr.strip()
        except subprocess.TimeoutExpired as exc:
            partial = b"".join(x for x in (exc.stdout, exc.stderr) if isinstance(x, bytes)).decode(errors="replace")
            code, why = -1, f"timed out after {WORKER_TIMEOUT:g} s"
            text = f"{partial}{why}\n"
        with lock:
            log.write(text)
            log.flush()
        rest = [job for job in remaining if not (out / job[0] / "status.json").exists()]
        if rest:
            folder = out / rest[0][0]
            folder.mkdir(parents=True, exist_ok=True)
            record = {"scenario": rest[0][1], "overrides": rest[0][2], "status": "crashed",
                      "message": f"worker exit code {code}: {why.splitlines()[-1] if why else 'no error output'}"}
            (folder / "status.json").write_text(json.dumps(record, indent=2))
            rest = rest[1:]
        remaining = rest


def _digest(src: Path) -> str:
    """sha256 of the .py and .toml files under `src`, by relative path and content."""
    h = hashlib.sha256()
    for path in sorted(p for p in src.rglob("*") if p.suffix in (".py", ".toml")):
        h.update(str(path.relative_to(src)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def capture(out: Path, src: Path, only: str | None, workers: int, extra: list[str]) -> int:
    """Run every variant of every packaged scenario of `src` into `out`, each with the overrides `extra` last (`--set`,
    e.g. simulation.log_every=1); 1 if any errored or crashed or `src` changed meanwhile."""
    src, out = src.resolve(), out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    env = _environment(src, out)
    where = subprocess.run([sys.executable, "-c", "import robotadapt; print(robotadapt.__file__)"], env=env,
                           capture_output=True, text=True, check=True).stdout.strip()
    if not Path(where).resolve().is_relative_to(src):
        print(f"robotadapt imports from {where}, not from {src}", file=sys.stderr)
        return 2
    groups = []
    for path in sorted((src / "robotadapt" / "studies" / "scenarios").glob("*.toml")):
        jobs = [(variant, scenario, overrides + extra)
                for variant, scenario, overrides in variants(path.stem, tomllib.loads(path.read_text(encoding="utf-8")))
                if only is None or fnmatch.fnmatch(variant, only)]
        if jobs:
            groups.append(jobs)
    start, before = time.perf_counter(), _digest(src)
    lock = threading.Lock()
    with open(out / "capture.log", "w", encoding="utf-8") as log:
        log.write(f"src {src} (digest {before})\nrobotadapt {where}\n")
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(lambda jobs: _run_scenario(jobs, out, env, log, lock), groups))
        seconds = time.perf_counter() - start
        statuses = [json.loads((out / job[0] / "status.json").read_text())["status"] for jobs in groups for job in jobs]
        counts = {s: statuses.count(s) for s in sorted(set(statuses))}
        after = _digest(src)
        summary = f"{len(statuses)} variants of {len(groups)} scenarios in {seconds:.0f} s: {counts}" + (
            "" if after == before else f"; {src} CHANGED during the capture (digest {after})")
        log.write(summary + "\n")
    print(f"robotadapt from {where}\n{summary}")
    return 1 if counts.get("error") or counts.get("crashed") or after != before else 0


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """The leaves of metrics.json by dotted key; a list of numbers is one leaf."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in _flatten(item, f"{prefix}{key}.").items()}
    return {prefix.rstrip("."): value}


def difference(a: Any, b: Any) -> float | None:
    """Max rel of the module docstring between two leaves or arrays; None if their shapes differ."""
    try:
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    except (TypeError, ValueError):
        return 0.0 if (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b) else math.inf
    if x.shape != y.shape:
        return None
    if x.size == 0:
        return 0.0
    same = (x == y) | (np.isnan(x) & np.isnan(y))
    if same.all():
        return 0.0
    both = np.abs(np.concatenate([x.ravel(), y.ravel()]))
    scale = float(both[np.isfinite(both)].max(initial=0.0))
    with np.errstate(invalid="ignore"):
        rel = np.abs(x - y) / np.maximum(np.maximum(np.abs(x), np.abs(y)), max(FLOOR * scale, 1e-300))
    rel = np.where(same, 0.0, np.nan_to_num(rel, nan=math.inf))
    return float(rel.max())


def compare_variant(a: Path, b: Path, keys: list[str] | None = None, skip: tuple[str, ...] = ()) -> tuple[str, float, str]:
    """(group, max rel, what is worst or missing) of one variant's folders; `keys`: only these metrics.json keys (two
    captures logged at different rates: the metrics every step folds), no result.npz; `skip`: every key but these
    (metrics.json keys, or result.npz arrays: a key one side adds)."""
    sa, sb = (json.loads((d / "status.json").read_text()) for d in (a, b))
    if sa["status"] != "ran" or sb["status"] != "ran":
        if sa["status"] == sb["status"] == "refused":
            return "refused", 0.0, sa["message"] if sa["message"] == sb["message"] else "messages differ"
        return "missing", math.nan, f"status {sa['status']} vs {sb['status']}"
    leaves = []
    ma, mb = (_flatten(json.loads((d / "metrics.json").read_text())) for d in (a, b))
    leaves += [(f"metrics:{k}", ma.get(k), mb.get(k), k in ma and k in mb) for k in sorted(ma.keys() | mb.keys())
               if k not in WALL_CLOCK and (keys is None or _top(k) in keys) and _top(k) not in skip]
    if keys is None:
        with np.load(a / "result.npz") as ra_, np.load(b / "result.npz") as rb_:
            na, nb = dict(ra_), dict(rb_)
        leaves += [(f"npz:{k}", na.get(k), nb.get(k), k in na and k in nb) for k in sorted(na.keys() | nb.keys())
                   if k not in skip]
    worst, where = 0.0, ""
    for key, x, y, both in leaves:
        rel = difference(x, y) if both else None
        if rel is None:
            return "missing", math.nan, f"{key} {'shape differs' if both else 'absent on one side'}"
        if rel > worst:
            worst, where = rel, key
    return ("equal" if worst <= EQUAL else "small" if worst <= SMALL else "large"), worst, where


def _top(key: str) -> str:
    """The metrics.json key a flattened key belongs to (`max_abs_torque[1]` → `max_abs_torque`)."""
    return key.split(".")[0].split("[")[0]


def compare(a_dir: Path, b_dir: Path, keys: list[str] | None = None, skip: tuple[str, ...] = ()) -> int:
    """Print one row per variant and the count per group; 1 if any variant is large or missing."""
    names = sorted({p.parent.name for d in (a_dir, b_dir) for p in d.glob("*/status.json")})
    rows = []
    for name in names:
        a, b = a_dir / name, b_dir / name
        if (a / "status.json").exists() and (b / "status.json").exists():
            rows.append((name, *compare_variant(a, b, keys, skip)))
        else:
            rows.append((name, "missing", math.nan, f"only in {a_dir if (a / 'status.json').exists() else b_dir}"))
    width = max((len(r[0]) for r in rows), default=7)
    print(f"{'variant':<{width}}  {'group':<8} {'max rel':>9}  worst / why")
    for name, group, rel, why in rows:
        print(f"{name:<{width}}  {group:<8} {rel:>9.3g}  {why}")
    groups = [r[1] for r in rows]
    counts = {g: groups.count(g) for g in ("equal", "small", "large", "missing", "refused")}
    print(f"{len(rows)} variants: " + ", ".join(f"{n} {g}" for g, n in counts.items())
          + f" (skipped wall-clock keys: {', '.join(WALL_CLOCK)})")
    return 1 if counts["large"] or counts["missing"] else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    cap = sub.add_parser("capture", help="run every scenario variant of one source tree into OUT_DIR")
    cap.add_argument("out", type=Path, metavar="OUT_DIR")
    cap.add_argument("--src", type=Path, default=DEFAULT_SRC, help="the source tree to import robotadapt from")
    cap.add_argument("--only", metavar="PATTERN", help="only the variants whose name matches this glob")
    cap.add_argument("--jobs", type=int, default=2, help="scenarios run at once (default 2)")
    cap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an override for every variant")
    cmp = sub.add_parser("compare", help="compare two captures")
    cmp.add_argument("a", type=Path, metavar="A_DIR")
    cmp.add_argument("b", type=Path, metavar="B_DIR")
    cmp.add_argument("--keys", help="compare only these metrics.json keys (comma-separated), no result.npz")
    cmp.add_argument("--skip", default="",
                     help="compare everything but these metrics.json keys or result.npz arrays (comma-separated)")
    work = sub.add_parser("_worker")  # internal: one scenario's variants in a fresh interpreter
    work.add_argument("out", type=Path)
    work.add_argument("jobs", type=json.loads)
    args = parser.parse_args()
    if args.command == "capture":
        return capture(args.out, args.src, args.only, args.jobs, args.set)
    if args.command == "compare":
        return compare(args.a, args.b, None if args.keys is None else args.keys.split(","),
                       tuple(filter(None, args.skip.split(","))))
    worker(args.out, [(variant, scenario, list(overrides)) for variant, scenario, overrides in args.jobs])
    return 0


if __name__ == "__main__":
    sys.exit(main())
