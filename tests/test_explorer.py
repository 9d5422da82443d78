"""The explorer (`robotadapt explore`, issue 46): the view in the URL and what it may name, latest-wins runs, the
controls of every law, the zip a run downloads, the server's Host/Origin guard, and the page in headless Chromium
driven by Playwright (one server and one browser for the module; benchmarks/bench_explorer.py holds the helpers and
measures the latency)."""

from __future__ import annotations

import contextlib
import http.client
import importlib.util
import io
import json
import os
import socket
import sys
import threading
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bokeh", reason="the explorer needs the extra [explore]: pip install 'robotadapt[explore]'")

from robotadapt.cli import main  # noqa: E402
from robotadapt.explorer.catalogue import Catalogue  # noqa: E402
from robotadapt.explorer.curves import MAX_POINTS, curves, single, thinned  # noqa: E402
from robotadapt.explorer.download import FILES, archive  # noqa: E402
from robotadapt.explorer.panels import PADDING, y_bounds  # noqa: E402
from robotadapt.explorer.runner import Runner  # noqa: E402
from robotadapt.explorer.server import allowed_hosts, local  # noqa: E402
from robotadapt.explorer.view import FIGURES, View, refuse_code  # noqa: E402
from robotadapt.studies.compare import number_text  # noqa: E402
from robotadapt.studies.scenarios import load  # noqa: E402
from robotadapt.validation import ConfigError  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("bench_explorer", ROOT / "benchmarks" / "bench_explorer.py")
bench = sys.modules.setdefault("bench_explorer", importlib.util.module_from_spec(_spec))  # type: ignore[arg-type]
_spec.loader.exec_module(bench)  # type: ignore[union-attr]
NO_BROWSER = bench.missing()
needs_browser = pytest.mark.skipif(NO_BROWSER is not None, reason=str(NO_BROWSER))


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def run_metrics(tmp_path: Path, *sets: str) -> dict:
    """metrics.json of `robotadapt run example-6.3.1 --set …`."""
    out = tmp_path / f"run{len(list(tmp_path.iterdir()))}"
    code, _, err = cli("run", "example-6.3.1", *[a for s in sets for a in ("--set", s)], "--no-plots", "--out", str(out))
    assert code == 0, err
    return json.loads((out / "metrics.json").read_text())


# ---------------------------------------------------------------------------------------------------------------------
# the view, the runs, the catalogue: no server


def test_a_view_round_trips_through_its_url():
    view = View("example-6.3.1", "pd", ("controller.Kv=20", "simulation.control_period=0.002"), large=True,
                hidden=("abs_e", "V"))
    query = view.query()
    assert query == ("?scenario=example-6.3.1&law=pd&fonts=large&hide=abs_e,V&set=controller.Kv=20"
                     "&set=simulation.control_period=0.002")
    arguments: dict[str, list[bytes]] = {}
    for part in query[1:].split("&"):
        key, _, value = part.partition("=")
        arguments.setdefault(key, []).append(value.encode())
    assert View.of_query(arguments, "other") == view
    assert View.of_query({}, "example-6.3.1") == View("example-6.3.1")
    assert view.with_set("controller.Kv", "30").sets == ("controller.Kv=30", "simulation.control_period=0.002")
    assert view.with_set("controller.Kv", " ").sets == ("simulation.control_period=0.002",)
    assert view.split() == (["simulation.control_period=0.002"], ["controller.Kv=20"])


@pytest.mark.parametrize("assignment", ['controller.kind="os:system"', "controller.kind=os:system",
                                        'controller={kind = "evil:Law", Kv = 1}', 'controller.law.kind="m:Update"',
                                        'controller.base={kind = "slotine_li", law = {kind = "m:C"}}',
                                        'robot.kind="mymod:Arm"', 'trajectory={kind = "m:path"}'])
def test_a_url_never_names_code(assignment):
    with pytest.raises(ConfigError, match="user kind") as info:
        refuse_code(assignment)
    assert "\n" not in str(info.value)
    view, refused = View("example-6.3.1", sets=("controller.Kv=20", assignment)).checked()
    assert view.sets == ("controller.Kv=20",) and len(refused) == 1
    with pytest.raises(ConfigError, match="user kind"):
        Catalogue("example-6.3.1").scenario(View("example-6.3.1", sets=(assignment,)))


def test_packaged_kinds_and_plain_values_are_no_code():
    for assignment in ('controller.kind="pd"', "controller.Kv=20", 'trajectory.kind="sinusoid"',
                       'plant.robot={kind = "two_link"}'):
        refuse_code(assignment)


def test_the_newest_change_wins_and_none_queues():
    """While a run is going, changes replace one another: the run under way ends (its result dropped), then only the
    newest runs and is reported."""
    started, release = threading.Event(), threading.Event()
    ran, reported = [], []
    done = threading.Event()

    def job(name: str, wait: bool = False):
        def run():
            ran.append(name)
            if wait:
                started.set()
                release.wait(5)
            return name
        return run

    def report(outcome):
        reported.append(outcome.value)
        done.set()

    with ThreadPoolExecutor(1) as executor:
        runner = Runner(executor, report)
        runner.submit(job("slow", wait=True))
        assert started.wait(5) and runner.started is not None
        for name in ("a", "b", "c"):
            runner.submit(job(name))
        release.set()
        assert done.wait(5)
    assert ran == ["slow", "c"] and reported == ["c"] and runner.started is None


def test_a_job_that_fails_reports_its_error():
    outcomes = []
    done = threading.Event()
    with ThreadPoolExecutor(1) as executor:
        runner = Runner(executor, lambda o: (outcomes.append(o), done.set()))
        runner.submit(lambda: (_ for _ in ()).throw(ConfigError("controller.Kv", "bad")))
        assert done.wait(5)
    assert isinstance(outcomes[0].error, ConfigError) and outcomes[0].value is None


@pytest.fixture(scope="module")
def catalogue() -> Catalogue:
    return Catalogue("example-6.3.1")


def test_the_gains_carry_their_unit_and_the_range_tune_screens(catalogue):
    controls = {c.key: c for c in catalogue.controls(View("example-6.3.1"))}
    assert list(controls) == ["controller.Lam", "controller.Kv", "controller.Gamma", "simulation.t_final",
                              "simulation.control_period", "plant.torque_limit", "plant.noise_q"]
    lam, kv, gamma = controls["controller.Lam"], controls["controller.Kv"], controls["controller.Gamma"]
    assert (lam.unit, kv.unit, gamma.unit) == ("1/s", "N·m·s/rad", "per parameter")
    assert lam.span == pytest.approx((0.25, 25.0)) and kv.span == pytest.approx((1.0, 100.0))  # tune: θ₀ ± ln 10
    assert kv.text == "10.0" and controls["simulation.t_final"].text == "10.0"
    assert controls["simulation.control_period"].text == "" and controls["plant.torque_limit"].span is None
    assert {c.key: c.text for c in catalogue.controls(View("example-6.3.1", sets=("controller.Kv=20",)))}[
        "controller.Kv"] == "20"


def test_every_law_that_applies_has_its_gains(catalogue):
    entries, skipped = catalogue.lineup(View("example-6.3.1"))
    assert not skipped and list(entries)[0] == "slotine_li" and entries["slotine_li"].reference
    for name in entries:
        gains = [c for c in catalogue.controls(View("example-6.3.1", name)) if c.key.startswith("controller.")]
        assert gains and all(c.unit and c.span for c in gains), name
    pd = {c.key: c for c in catalogue.controls(View("example-6.3.1", "pd"))}
    assert pd["controller.Kp"].unit == "N·m/rad" and pd["controller.Kp"].default == 25.0  # K_v Λ of Example 6.3.1


def test_the_view_runs_what_robotadapt_run_runs(catalogue, tmp_path):
    view = View("example-6.3.1", sets=("controller.Kv=20", "simulation.t_final=2"))
    run = catalogue.run(view)
    assert run.scenario.text == load("example-6.3.1", list(view.sets)).text
    written = run_metrics(tmp_path, *view.sets)
    assert {k: v for k, v in written.items() if k != "wall_time_s"} == \
        {k: v for k, v in json.loads(json.dumps(run.metrics)).items() if k != "wall_time_s"}
    assert catalogue.run(view) is run  # the same view again: the run kept


def test_the_curves_are_the_runs_samples_thinned_in_single_precision(catalogue):
    for n in (1, 7, 999, 1000, 1001, 10001):
        keep = thinned(n)
        assert keep[0] == 0 and keep[-1] == n - 1 and np.all(np.diff(keep) > 0) and keep.size <= MAX_POINTS + 1
        if keep.size > 2:
            assert np.ptp(np.diff(keep[:-1])) == 0  # evenly strided but for the last
    res = catalogue.run(View("example-6.3.1")).result
    shown = curves(catalogue.run(View("example-6.3.1")))
    keep = thinned(res.t.size)
    assert [p.name for p in shown.panels] == list(FIGURES) == ["e", "abs_e", "phi", "tau", "V"]
    assert shown.data["t"].tolist() == res.t[keep].tolist()
    for column, values in (("e1", res.e[keep, 1]), ("abs_e0", np.abs(res.e[keep, 0])), ("tau1", res.tau[keep, 1]),
                           ("phi0", res.phi_hat[keep, 0]), ("V0", res.V[keep])):
        assert shown.data[column].dtype == np.float32, column
        finite = np.isfinite(shown.data[column])
        np.testing.assert_allclose(shown.data[column][finite], values[finite], rtol=1e-7, atol=1e-30, err_msg=column)
    big = np.array([0.0, 1e-50, -1e-50, 1e50, -1e50, np.nan, -2.25])
    assert single(big).tolist()[:5] == [0.0, np.finfo(np.float32).tiny, -np.finfo(np.float32).tiny,
                                        np.finfo(np.float32).max, -np.finfo(np.float32).max]
    assert np.isnan(single(big)[5]) and single(big)[6] == -2.25


def test_the_y_axes_fit_the_finite_values_with_padding():
    low, high = y_bounds([np.array([1.0, np.nan, 3.0]), np.array([-1.0, np.inf])], log=False)
    assert (low, high) == pytest.approx((-1.0 - 4 * PADDING, 3.0 + 4 * PADDING))
    low, high = y_bounds([np.array([0.0, 1e-6, 1e-2, -5.0])], log=True)  # decades of the positive values
    assert (np.log10(low), np.log10(high)) == pytest.approx((-6 - 4 * PADDING, -2 + 4 * PADDING))
    assert y_bounds([np.array([2.0, 2.0])], log=False) == pytest.approx((2 - 2 * PADDING, 2 + 2 * PADDING))
    assert y_bounds([np.array([np.nan])], log=False) == (-1.0, 1.0) and y_bounds([], log=True) == (0.1, 10.0)


def test_only_packaged_scenarios_and_the_command_lines_file(catalogue, tmp_path):
    with pytest.raises(ConfigError, match="not a scenario of this explorer"):
        catalogue.source("/etc/passwd")
    with pytest.raises(ConfigError, match="not a scenario of this explorer"):
        catalogue.lineup(View("../secret.toml"))
    with pytest.raises(ConfigError, match="law: 'nope' does not apply"):
        catalogue.entry(View("example-6.3.1", "nope"))
    mine = tmp_path / "my-arm.toml"
    mine.write_text(load("example-6.3.1", ["simulation.t_final=1"]).text)
    own = Catalogue(mine)
    assert own.default == "my-arm" and own.names[0] == "my-arm" and "example-6.3.1" in own.names
    assert own.run(View("my-arm")).result.ok


def test_the_download_holds_what_robotadapt_run_reproduces(catalogue, tmp_path):
    run = catalogue.run(View("example-6.3.1", "pd", ("controller.Kv=15", "simulation.t_final=1")))
    with zipfile.ZipFile(io.BytesIO(archive(run))) as z:
        assert sorted(z.namelist()) == sorted(FILES)
        z.extractall(tmp_path / "zip")
    again = load(tmp_path / "zip" / "scenario.toml").run()
    written = json.loads((tmp_path / "zip" / "metrics.json").read_text())
    assert written["rms_error"] == run.metrics["rms_error"]
    assert np.array_equal(again.e, run.result.e)
    with np.load(tmp_path / "zip" / "result.npz") as npz:
        assert np.array_equal(npz["tau"], run.result.tau)


def test_hosts_and_origins_the_guard_allows():
    allowed = allowed_hosts("127.0.0.1", 5006, ["lecture-pc.local:5006"])
    assert local({"Host": "127.0.0.1:5006"}, allowed) and local({"Host": "localhost:5006"}, allowed)
    assert local({"Host": "LOCALHOST:5006", "Origin": "http://127.0.0.1:5006"}, allowed)
    assert local({"Host": "lecture-pc.local:5006", "Origin": "http://lecture-pc.local:5006"}, allowed)
    for headers in ({"Host": "evil.example:5006"}, {"Host": "127.0.0.1:5007"}, {},
                    {"Host": "127.0.0.1:5006", "Origin": "http://evil.example"},
                    {"Host": "127.0.0.1:5006", "Origin": "null"},
                    {"Host": "127.0.0.1:5006", "Origin": "http://127.0.0.1:5006.evil.example"}):
        assert not local(headers, allowed), headers


def test_explore_refuses_a_bad_scenario_in_one_line():
    code, _, err = cli("explore", "no-such-scenario", "--no-browser", "--port", "0")
    assert code == 2 and err.count("\n") == 1 and err.startswith("robotadapt: error: scenario: unknown scenario")


# ---------------------------------------------------------------------------------------------------------------------
# the server: raw HTTP


@pytest.fixture(scope="module")
def served():
    running = bench.serve()
    yield running
    running.stop()


def request(served, path: str = "/", **headers: str) -> tuple[int, bytes]:
    connection = http.client.HTTPConnection("127.0.0.1", served.port, timeout=60)
    connection.putrequest("GET", path, skip_host=True)
    for name, value in {"Host": f"127.0.0.1:{served.port}", **headers}.items():
        connection.putheader(name, value)
    connection.endheaders()
    reply = connection.getresponse()
    try:
        return reply.status, reply.read()
    finally:
        connection.close()


def listening(port: int) -> set[str]:
    """The local addresses listening on `port` (Linux: /proc/net/tcp, tcp6)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with contextlib.suppress(OSError), open(table) as f:
            for line in f.readlines()[1:]:
                local_address, state = line.split()[1], line.split()[3]
                address, _, hex_port = local_address.rpartition(":")
                if state == "0A" and int(hex_port, 16) == port:  # LISTEN
                    found.add(socket.inet_ntop(socket.AF_INET, bytes.fromhex(address)[::-1]) if len(address) == 8
                              else address)
    return found


def test_it_serves_within_ten_seconds_on_the_loopback_address_only(served):
    assert served.seconds <= 10.0
    assert served.url == f"http://127.0.0.1:{served.port}/"
    if Path("/proc/net/tcp").exists():
        assert listening(served.port) == {"127.0.0.1"}


def test_requests_for_another_host_or_from_another_origin_are_refused(served):
    status, page = request(served)
    assert status == 200 and b"/static/js/bokeh" in page and b"cdn.bokeh.org" not in page  # BokehJS from itself
    script = page.split(b'src="')[1].split(b'"')[0].decode()
    assert request(served, script)[0] == 200
    rebinding = {"Host": f"attacker.example:{served.port}"}
    cross_site = {"Origin": "http://attacker.example"}
    upgrade = {"Upgrade": "websocket", "Connection": "Upgrade", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}
    for path in ("/", script, "/ws", "/download?scenario=example-6.3.1"):
        for headers in (rebinding, cross_site, {**upgrade, **cross_site}, {**upgrade, **rebinding}):
            status, body = request(served, path, **headers)
            assert status == 403 and body.startswith(b"robotadapt explore: refused"), (path, headers)


def test_a_download_url_runs_no_code_and_no_other_file(served):
    status, body = request(served, "/download?scenario=example-6.3.1&set=controller.kind=os:system")
    assert status == 400 and body.decode().startswith("robotadapt: error: controller.kind: names a user kind")
    assert body.decode().count("\n") == 1
    status, body = request(served, "/download?scenario=/etc/passwd")
    assert status == 400 and b"not a scenario of this explorer" in body
    status, body = request(served, "/download?scenario=example-6.3.1&set=controller.Kv=20")
    with zipfile.ZipFile(io.BytesIO(body)) as z:
        assert status == 200 and sorted(z.namelist()) == sorted(FILES)
        assert b"Kv = 20" in z.read("scenario.toml")


def test_ctrl_c_stops_it_cleanly_and_frees_the_port():
    running = bench.serve()
    assert running.seconds <= 10.0
    assert running.stop() == 0
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", running.port), timeout=5).close()
    with socket.socket() as s:  # free for the next server (as a server binds: its closed connections may linger)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", running.port))
        s.listen()


# ---------------------------------------------------------------------------------------------------------------------
# the page in headless Chromium


@pytest.fixture(scope="module")
def chromium():
    if NO_BROWSER is not None:
        pytest.skip(NO_BROWSER)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = bench.browser(p)
        yield browser
        browser.close()


def page_of(chromium, served, view: View):
    """The page of `view`, drawn, with every request that leaves this machine refused (the page works offline)."""
    page = chromium.new_page(viewport=bench.VIEWPORT)
    outside: list[str] = []

    def route(request_route):
        if request_route.request.url.startswith(served.url):
            request_route.continue_()
        else:
            outside.append(request_route.request.url)
            request_route.abort()

    page.route("**/*", route)
    page.add_init_script(bench.RELEASE)
    page.goto(served.page(view))
    page.wait_for_function("window.robotadaptDrawn !== undefined && window.robotadaptDrawn.run >= 1", timeout=120_000)
    bench.settled(page)
    page.wait_for_timeout(300)
    assert not outside, outside
    return page


def model(page, name: str, attribute: str):
    return page.evaluate(f"Bokeh.documents[0].get_model_by_name({name!r}).{attribute}")


def rows(page) -> dict[str, str]:
    data = model(page, "metrics", "data")
    return dict(zip(data["metric"], data["value"], strict=True))


def displayed(page) -> dict[str, list[str]]:
    """The metrics table's rows as the browser shows them (the rows in view): metric → [this run, pinned run]."""
    cells = page.locator(".slick-cell").all_inner_texts()
    return {cells[i]: cells[i + 1:i + 3] for i in range(0, len(cells) - 2, 3)}


def field(page, key: str):
    return page.locator(f".{bench.css_class(key)} input")


@needs_browser
def test_the_url_shows_what_robotadapt_run_writes_to_its_printed_digits(chromium, served, tmp_path):
    page = page_of(chromium, served, View("example-6.3.1", sets=("controller.Kv=20",)))
    written = run_metrics(tmp_path, "controller.Kv=20")
    assert field(page, "controller.Kv").input_value() == "20"
    shown = rows(page)
    for key in ("rms_error", "rms_error_norm", "final_abs_error", "max_abs_torque", "final_phi_hat"):
        assert shown[key] == number_text(written[key]), key
    assert f"<b>rms_error</b> {number_text(written['rms_error'])}" in model(page, "status", "text")  # the headline
    page.close()


#: Bokeh's own paint put back on a page, and the reads of the visuals' CSS variables counted
BOKEH_PAINT = """() => {
  const own = window.robotadaptPaint, read = CSSStyleDeclaration.prototype.getPropertyValue;
  own.visual._get_css_value = own.css;
  own.sheet._update = own.update;
  window.cssReads = 0;
  CSSStyleDeclaration.prototype.getPropertyValue = function (name) {
    if (name.startsWith("--bk-")) { window.cssReads++; }
    return read.call(this, name);
  };
}"""


@needs_browser
def test_the_faster_paint_draws_what_bokeh_draws(chromium, served):
    """The page's changes to BokehJS's paint (PAINT_JS) are in effect, and the figures they paint are Bokeh's own to
    the pixel: two pages of one view, made narrower and back (which repaints every figure), one with Bokeh's own
    functions put back (which read the visuals' CSS variables), show the same figures."""
    shots, reads = [], []
    for own in (False, True):
        page = page_of(chromium, served, View("example-6.3.1", sets=("controller.Kv=20",)))
        assert page.evaluate("window.robotadaptPaint.visual._get_css_value('line-color')") == ""
        if own:
            page.evaluate(BOKEH_PAINT)
        for size in ({"width": bench.VIEWPORT["width"] - 200, "height": bench.VIEWPORT["height"]}, bench.VIEWPORT):
            page.set_viewport_size(size)
            page.wait_for_timeout(500)
        reads.append(page.evaluate("window.cssReads"))
        shots.append(page.locator(".ra-grid").screenshot())
        page.close()
    assert reads[0] is None and reads[1] > 0
    assert shots[0] == shots[1]


@needs_browser
def test_a_slider_redraws_the_figures_and_the_metrics_as_robotadapt_run_would(chromium, served, tmp_path):
    page = page_of(chromium, served, View("example-6.3.1"))
    curve = "Array.from(Bokeh.documents[0].get_model_by_name('curves').data.e1)"
    before_curve, before = page.evaluate(curve), rows(page)
    ms = bench.drag(page, "controller.Kv", 0.8)
    bench.settled(page)
    after_curve, after = page.evaluate(curve), rows(page)
    assert after_curve != before_curve and after["rms_error"] != before["rms_error"]
    assert "set=controller.Kv=" in page.url
    kv = page.url.split("set=controller.Kv=")[1].split("&")[0]
    assert field(page, "controller.Kv").input_value() == kv and 30 < float(kv) < 50  # ≈ 80 % of 1 … 100 on a log scale
    written = run_metrics(tmp_path, f"controller.Kv={kv}")
    assert after["rms_error"] == number_text(written["rms_error"])
    assert after["max_abs_torque"] == number_text(written["max_abs_torque"])
    assert displayed(page)["rms_error"][0] == after["rms_error"]
    print(f"slider release to redrawn figures: {ms:.0f} ms")
    page.close()


@needs_browser
def test_a_bad_value_gets_the_command_lines_line_beside_its_field(chromium, served):
    page = page_of(chromium, served, View("example-6.3.1"))
    before = bench.drawn(page)
    field(page, "controller.Kv").fill("-5")
    field(page, "controller.Kv").press("Enter")
    page.wait_for_function(f"window.robotadaptDrawn.run > {before}")
    bench.settled(page)
    code, _, err = cli("run", "example-6.3.1", "--set", "controller.Kv=-5", "--no-plots")
    assert code == 2
    message = model(page, "error-controller.Kv", "text")
    assert err.strip() == f"robotadapt: error: {message}"
    assert "controller.Kv=-5" in page.url  # the link shows the same
    page.close()


@needs_browser
def test_a_url_naming_code_is_refused_with_one_line_and_runs_the_rest(chromium, served):
    page = page_of(chromium, served, View("example-6.3.1", sets=('controller.kind="os:system"', "controller.Kv=20")))
    assert model(page, "message", "text").startswith("controller.kind: names a user kind")
    assert "os:system" not in page.url and "controller.Kv=20" in page.url
    assert field(page, "controller.Kv").input_value() == "20"
    page.close()


@needs_browser
def test_the_url_round_trips_and_pinning_keeps_a_run_beneath(chromium, served):
    page = page_of(chromium, served, View("example-6.3.1"))
    page.locator(".ra-pin button").click()
    pinned = rows(page)
    before = bench.drawn(page)
    page.locator(".ra-law select").select_option(label="PD")
    page.wait_for_function(f"window.robotadaptDrawn.run > {before}")
    bench.settled(page)
    before = bench.drawn(page)
    field(page, "simulation.t_final").fill("5")
    field(page, "simulation.t_final").press("Enter")
    page.wait_for_function(f"window.robotadaptDrawn.run > {before}")
    bench.settled(page)
    assert "law=pd" in page.url and "set=simulation.t_final=5" in page.url
    assert displayed(page)["rms_error"] == [rows(page)["rms_error"], pinned["rms_error"]]
    assert rows(page)["t_end"] == "5"
    again = chromium.new_page(viewport=bench.VIEWPORT)
    again.goto(page.url)
    again.wait_for_function("window.robotadaptDrawn !== undefined && window.robotadaptDrawn.run >= 1")
    bench.settled(again)
    assert rows(again) == rows(page)
    assert model(again, "law", "value") == "pd" and field(again, "simulation.t_final").input_value() == "5"
    again.close()
    page.close()


@needs_browser
def test_hidden_figures_leave_the_page_and_the_url_keeps_them(chromium, served):
    figures = ("Bokeh.documents[0].roots().filter(r => r.name && r.name.startsWith('slot'))"
               ".flatMap(r => r.children).filter(c => c.type === 'Figure').length")
    page = page_of(chromium, served, View("example-6.3.1", hidden=("abs_e",)))
    assert page.evaluate(figures) == 4 and model(page, "figures", "active") == [0, 2, 3, 4]
    page.locator(".bk-btn-group button", has_text="V").click()  # hide V as well
    page.wait_for_function(f"{figures} === 3")
    page.wait_for_function("window.location.search.includes('hide=abs_e,V')")  # (history.replaceState: not page.url)
    before = bench.drawn(page)
    field(page, "controller.Kv").fill("30")
    field(page, "controller.Kv").press("Enter")
    page.wait_for_function(f"window.robotadaptDrawn.run > {before}")
    assert "hide=abs_e,V" in page.evaluate("window.location.search") and page.evaluate(figures) == 3
    page.locator(".bk-btn-group button", has_text="|e| (log)").click()  # shown again, with the newest run's data
    page.wait_for_function(f"{figures} === 4")
    page.wait_for_function("window.location.search.includes('hide=V')")
    page.close()


@needs_browser
def test_the_y_axes_hold_as_the_gains_move_until_fitted_again(chromium, served):
    axis = "Bokeh.documents[0].get_model_by_name('figure-e').y_range"
    y_range = f"[{axis}.start, {axis}.end]"
    page = page_of(chromium, served, View("example-6.3.1"))
    data = "['e0', 'e1'].flatMap(c => Array.from(Bokeh.documents[0].get_model_by_name('curves').data[c]))"
    held = page.evaluate(y_range)
    e = np.array(page.evaluate(data), dtype=float)
    assert held[0] <= np.nanmin(e) and np.nanmax(e) <= held[1]  # fitted to the first run
    bench.drag(page, "controller.Kv", 0.95)  # a much larger K_v: a much smaller error
    bench.settled(page)
    assert page.evaluate(y_range) == held
    e = np.array(page.evaluate(data), dtype=float)
    page.get_by_role("button", name="fit axes").click()
    page.wait_for_function(f"{axis}.end !== {held[1]}")
    fitted = page.evaluate(y_range)
    span = np.nanmax(e) - np.nanmin(e)
    assert fitted == pytest.approx([np.nanmin(e) - PADDING * span, np.nanmax(e) + PADDING * span], rel=1e-6)
    page.close()


@needs_browser
def test_the_latency_of_a_slider_on_example_631(chromium, served):
    """From a slider's release to the redrawn figures (benchmarks/bench_explorer.py: the goal, p50 ≤ 150 ms)."""
    page = page_of(chromium, served, View("example-6.3.1"))
    ms = bench.latencies(page, "controller.Kv", 5)
    p50 = float(np.median(ms))
    print(f"example-6.3.1: slider release to redrawn figures p50 {p50:.0f} ms, max {ms.max():.0f} ms "
          f"(load average {os.getloadavg()[0]:.1f})")
    assert p50 <= 1000.0  # a sanity bound here (other tests share the cores); the benchmark reports the goal
    page.close()


@needs_browser
@pytest.mark.slow
def test_the_latency_of_a_slider_on_the_panda(chromium, served):
    page = page_of(chromium, served, View("panda-slotine-li", sets=("simulation.t_final=2",)))
    ms = bench.latencies(page, "controller.Lam", 5)
    print(f"panda-slotine-li (2 s): slider release to redrawn figures p50 {np.median(ms):.0f} ms")
    assert np.median(ms) <= 1500.0
    page.close()
