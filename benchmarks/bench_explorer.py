"""Latency of `robotadapt explore` (issue 46; run by `make bench`; tests/test_explorer.py uses its helpers).

Starts `robotadapt explore example-6.3.1 --port 0 --no-browser` as a user would (the serving time: from the command to
the first page answered), opens the page in headless Chromium driven by Playwright, and drags a gain's slider with the
mouse, each drag to a new value (a new run, none from the explorer's cache): the latency of a drag is from the mouse's
release (`pointerup`, in the page's clock) to the redrawn figures (the page's `window.robotadaptDrawn`, set just after
the animation frame that paints the run's data). Prints p50, p99 and max per scenario as a markdown table, with the
goals (p50 ≤ 150 ms for Example 6.3.1, 10 s at 1 kHz, its five figures shown; ≤ 1.5 s for the Panda's Slotine–Li over
2 s), Example 6.3.1 again with two figures hidden, and the machine's load average before and after (other processes
on the two cores show up in every number).

The page marks each outcome it shows in `window.robotadaptDrawn` (`{run, t}`): the run's figures redrawn, or its
refusal shown. `--against SRC` alternates Example 6.3.1's drags with the explorer of another source tree (the effect
of a change, measured under one load). `--screenshot PATH` writes the docs' picture instead (docs/img/explorer.png):
Example 6.3.1 at the book's gains pinned, then K_v = 40.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robotadapt.explorer.app import css_class
from robotadapt.explorer.view import View

CHROMIUM = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
ROBOTADAPT = str(Path(sys.executable).with_name("robotadapt"))
#: (scenario, its settings, the figures hidden, the slider dragged, drags, goal of p50 in ms; None: none)
CASES = (("example-6.3.1", (), (), "controller.Kv", 20, 150.0),
         ("example-6.3.1", (), ("abs_e", "V"), "controller.Kv", 20, None),
         ("panda-slotine-li", ("simulation.t_final=2",), (), "controller.Lam", 10, 1500.0))
RELEASE = "document.addEventListener('pointerup', () => { window.robotadaptReleased = performance.now(); }, true)"
VIEWPORT = {"width": 1600, "height": 1000}


def missing() -> str | None:
    """Why the browser cannot be driven here; None when it can."""
    if CHROMIUM is None:
        return "no chromium binary: install Debian's `chromium` package (apt-get install -y chromium)"
    if importlib.util.find_spec("playwright") is None:
        return "no playwright: pip install playwright (or 'robotadapt[dev]'); it drives the system's chromium"
    return None


@dataclass
class Served:
    """A running `robotadapt explore`: its process, URL, port and the seconds from the command to the first page."""

    process: subprocess.Popen[str]
    url: str
    port: int
    seconds: float
    log: Path

    def page(self, view: View) -> str:
        """The URL of `view`."""
        return self.url.rstrip("/") + "/" + view.query()

    def stop(self, timeout: float = 20.0) -> int:
        """Ctrl-C (SIGINT) and the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        return self.process.wait(timeout)


def serve(scenario: str = "example-6.3.1", *args: str, timeout: float = 60.0, source: Path | None = None) -> Served:
    """Start `robotadapt explore SCENARIO --port 0 --no-browser ARGS` and wait for its first page; `source`: the
    package from that source tree (its `src`, first on PYTHONPATH) instead of the installed one."""
    log = Path(tempfile.mkstemp(prefix="robotadapt-explore-", suffix=".log")[1])
    started = time.perf_counter()
    command = [ROBOTADAPT] if source is None else [sys.executable, "-m", "robotadapt"]
    env = None if source is None else {**os.environ, "PYTHONPATH": str(source)}
    process = subprocess.Popen([*command, "explore", scenario, "--port", "0", "--no-browser", *args],
                               stdout=subprocess.PIPE, stderr=log.open("w"), text=True, env=env)
    assert process.stdout is not None
    line = process.stdout.readline()
    found = re.search(r"(http://\S+?:(\d+)/)", line)
    if found is None:
        process.kill()
        raise RuntimeError(f"robotadapt explore did not start: {line!r} {log.read_text()[-2000:]}")
    while True:
        try:
            with urllib.request.urlopen(found.group(1), timeout=timeout) as reply:
                reply.read()
            break
        except OSError:
            if time.perf_counter() - started > timeout:
                raise
            time.sleep(0.05)
    return Served(process, found.group(1), int(found.group(2)), time.perf_counter() - started, log)


def browser(playwright: Any) -> Any:
    """Headless Chromium: the system's, not a download."""
    return playwright.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])


def open_page(chromium: Any, url: str, timeout: float = 120_000) -> Any:
    """A page of the explorer at `url`, once it shows its first run (drawn, or refused) and has laid out its fields."""
    page = chromium.new_page(viewport=VIEWPORT)
    page.add_init_script(RELEASE)
    page.goto(url)
    page.wait_for_function("window.robotadaptDrawn !== undefined && window.robotadaptDrawn.run >= 1", timeout=timeout)
    settled(page)
    page.wait_for_timeout(300)  # the fields' layout settles (a handle read while it moves is missed)
    return page


def settled(page: Any, timeout: float = 60_000) -> None:
    """Wait for the text that follows the figures of the run drawn last (its metrics, its status line)."""
    page.wait_for_function("Bokeh.documents[0].get_model_by_name('status').text.includes("
                           "'run ' + window.robotadaptDrawn.run + ':')", timeout=timeout)


def drawn(page: Any) -> int:
    """The ticket of the run the page drew last."""
    return int(page.evaluate("window.robotadaptDrawn.run"))


def drag(page: Any, key: str, fraction: float, timeout: float = 60_000) -> float:
    """Drag the slider of `key` with the mouse to `fraction` of its track; the milliseconds from the release to the
    redrawn figures."""
    css = css_class(key) + "-slider"
    track = page.locator(f".{css} .noUi-base").bounding_box()
    handle = page.locator(f".{css} .noUi-handle").bounding_box()
    x, y = handle["x"] + handle["width"] / 2, handle["y"] + handle["height"] / 2
    before = drawn(page)
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(track["x"] + fraction * track["width"], y, steps=4)
    page.mouse.up()
    page.wait_for_function(f"window.robotadaptDrawn.run > {before}", timeout=timeout)
    return float(page.evaluate("window.robotadaptDrawn.t - window.robotadaptReleased"))


#: between two drags, as a lecturer looks at the figures (the page settles: Bokeh reports the figures' new sizes)
PAUSE = 0.5


def latencies(page: Any, key: str, count: int) -> np.ndarray:
    """`count` drags of `key`'s slider, from 12 % of its track to 92 % (a new value each: no run repeats), `PAUSE`
    apart, ms."""
    drag(page, key, 0.1)  # from wherever it stands: not measured
    out = []
    for k in range(count):
        time.sleep(PAUSE)
        out.append(drag(page, key, 0.12 + 0.8 * (k + 1) / count))
    return np.array(out)


def paired(source: Path, count: int = 30) -> None:
    """Example 6.3.1's drags alternated between this package's explorer and the one of the source tree `source` (a
    `src` directory, e.g. of `git worktree add /tmp/before HEAD~1`), each in a page of its own: the p50 of each, as
    a markdown table. Both share the machine's load, drag for drag: a change's effect shows where two separate runs
    of the benchmark differ by more than it."""
    from playwright.sync_api import sync_playwright

    servers = {"this package": serve(), str(source): serve(source=source)}
    try:
        with sync_playwright() as p:
            chromium = browser(p)
            pages = {name: open_page(chromium, s.page(View("example-6.3.1"))) for name, s in servers.items()}
            for page in pages.values():
                drag(page, "controller.Kv", 0.1)
            ms: dict[str, list[float]] = {name: [] for name in pages}
            for k in range(count):
                for name, page in pages.items():
                    page.bring_to_front()
                    time.sleep(PAUSE)
                    ms[name].append(drag(page, "controller.Kv", 0.12 + 0.8 * (k + 1) / count))
            chromium.close()
    finally:
        for s in servers.values():
            s.stop()
    print("| explorer | drags | p50 (ms) | mean (ms) |")
    print("|---|---|---|---|")
    for name, values in ms.items():
        print(f"| {name} | {count} | {np.median(values):.0f} | {np.mean(values):.0f} |")


def screenshot(path: Path) -> None:
    """The docs' picture: Example 6.3.1 at the book's gains pinned beneath K_v = 40."""
    from playwright.sync_api import sync_playwright

    served = serve()
    try:
        with sync_playwright() as p:
            chromium = browser(p)
            page = open_page(chromium, served.page(View("example-6.3.1")))
            page.get_by_role("button", name="pin this run").click()
            before = drawn(page)
            field = page.locator(f".{css_class('controller.Kv')} input")
            field.fill("40")
            field.press("Enter")
            page.wait_for_function(f"window.robotadaptDrawn.run > {before}", timeout=60_000)
            page.mouse.move(0, 0)
            page.screenshot(path=str(path), full_page=True)
            chromium.close()
    finally:
        served.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--screenshot", type=Path, metavar="PATH", help="write the docs' picture and exit")
    parser.add_argument("--against", type=Path, metavar="SRC",
                        help="alternate Example 6.3.1's drags with the explorer of another source tree's src directory")
    args = parser.parse_args()
    why = missing()
    if why:
        print(f"skipped: {why}")
        return 0
    if args.screenshot:
        screenshot(args.screenshot)
        print(f"wrote {args.screenshot}")
        return 0
    if args.against:
        if not (args.against / "robotadapt" / "__init__.py").is_file():
            print(f"--against: {args.against} holds no robotadapt package; give a source tree's src directory")
            return 2
        paired(args.against)
        return 0
    from playwright.sync_api import sync_playwright

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    served = serve()
    print(f"`robotadapt explore example-6.3.1` served its first page {served.seconds:.2f} s after the command (goal ≤ 10 s)")
    print("| scenario | drags | p50 (ms) | p99 (ms) | max (ms) | goal p50 (ms) |")
    print("|---|---|---|---|---|---|")
    try:
        with sync_playwright() as p:
            chromium = browser(p)
            for scenario, sets, hidden, key, count, goal in CASES:
                page = open_page(chromium, served.page(View(scenario, sets=sets, hidden=hidden)))
                ms = latencies(page, key, count)
                p50, p99 = np.percentile(ms, [50, 99])
                shown = f"{scenario}" + "".join(f" --set {s}" for s in sets) + (f", {', '.join(hidden)} hidden"
                                                                                 if hidden else "")
                target = "—" if goal is None else f"{goal:g}"
                print(f"| {shown} | {count} | {p50:.0f} | {p99:.0f} | {ms.max():.0f} | {target} |", flush=True)
                page.close()
            chromium.close()
    finally:
        code = served.stop()
    print(f"load average at the end: {os.getloadavg()[0]:.2f}; Ctrl-C stopped the server with exit code {code}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
