"""The live page in a real headless Chromium (Debian's chromium + chromium-driver, driven by
selenium; WebGL through SwiftShader), against the simulated board.

The tests run in file order on one capture: the page loads before any data; the capture
starts and the sphere fills; the fit converges to the simulator's truth; the page's numbers
equal /api/state; Save writes what `triaxcal fit` writes; nothing left 127.0.0.1 and the
console stayed clean (one of these run on its own, as with ``pytest -k``, loads the page and
runs the capture first). Then a second capture has its cable pulled. The README's screenshot,
``docs/live.png``, is taken here and written only when ``TRIAXCAL_UPDATE_SCREENSHOT=1``
(``make screenshot``), so that a test run leaves the checkout as it found it. Every wait is on
a condition with a generous limit, so a loaded machine only makes the tests slower.

Skipped only when chromium or chromedriver is missing (``make deps`` installs both; CI does).
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from triaxcal.calibration import Calibration
from triaxcal.capture.run import capture, channel_names
from triaxcal.cli import main
from triaxcal.io.serial import SerialReader
from triaxcal.live import LiveOptions, LiveState
from triaxcal.live.server import LiveServer
from triaxcal.sim import SimDevice, SimIMU, globe_script, tumble_script

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
if CHROMIUM is None or CHROMEDRIVER is None:
    pytest.skip("the live page's browser tests need Debian's chromium and chromium-driver "
                "(make deps installs them)", allow_module_level=True)

NAMES = channel_names("framed", 10)
SEED = 7


def wait_for(cond: Any, timeout: float, what: str, every: float = 0.25) -> Any:
    """Poll ``cond()`` until it returns something true; fail saying ``what`` after ``timeout``."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        last = cond()
        if last:
            return last
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what} (last: {last!r})")


@pytest.fixture(scope="module")
def driver():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
              "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
              # the page itself rastered by the CPU (SwiftShader only for WebGL): much faster
              "--disable-gpu-rasterization", "--disable-accelerated-2d-canvas",
              "--window-size=1400,1400", "--hide-scrollbars", "--no-first-run",
              "--disable-extensions", "--disable-background-networking", "--disable-sync",
              "--disable-component-update", "--disable-default-apps"):
        opts.add_argument(a)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    d = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    try:
        d.set_page_load_timeout(240)
        d.set_script_timeout(120)
        yield d
    finally:
        d.quit()


class Run:
    """One capture from the simulated board with the page open."""

    def __init__(self, tmp: Path, *, script: Any, speed: float, loop: bool, mag_radius: Any):
        self.imu = SimIMU(SEED)
        # the board is plugged in (its script clock starts) only when the capture starts
        self.dev = SimDevice(self.imu, script, speed=speed, loop=loop, seed=SEED,
                             link=tmp / "ttySIM0")
        self.reader = SerialReader(self.dev.port, protocol="framed", channels=10)
        self.session = tmp / "session.csv"
        self.state = LiveState(self.session, NAMES, port=self.dev.port,
                               options=LiveOptions(mag_radius=mag_radius, out_dir=tmp / "out"))
        self.state.attach(self.reader)
        self.server = LiveServer(self.state, port=0).start()
        self.state.start()
        self.stop = threading.Event()
        self.result: Any = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._capture, daemon=True)

    def _capture(self) -> None:
        try:
            self.dev.start()
            self.result = capture(self.reader, self.session, stop=self.stop if self.dev.loop
                                  else self.dev.finished, on_records=self.state.on_records,
                                  progress=None, bell=False, handle_sigint=False)
            self.state.finish(self.result)
        except BaseException as exc:  # noqa: BLE001 - reported by the tests
            self.error = exc

    def api(self) -> dict:
        with urllib.request.urlopen(self.server.url + "api/state", timeout=60) as r:
            return json.load(r)

    def close(self) -> None:
        self.stop.set()
        self.dev.silence(30.0)
        self.thread.join(60)
        self.state.stop()
        self.server.stop()
        self.dev.stop()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    # the globe scheme, then a tumble through 30 random orientations (as `demo --live`); the
    # default pose detection (offline, on this script for 6 seeds x 4 start offsets, the
    # largest |error| / std. error of the nine accelerometer terms was at most 3.2)
    script = globe_script(hold_s=1.0, seed=SEED) + tumble_script(30, seed=SEED)
    r = Run(tmp_path_factory.mktemp("live"), script=script, speed=4.0, loop=False,
            mag_radius="50uT")
    try:
        yield r
    finally:
        r.close()


@pytest.fixture
def finished(driver, run):
    """The capture of ``run`` ended, with the page open: what the tests after the one that
    watches the sphere fill see (when one of them runs on its own, it starts both here)."""
    if not driver.current_url.startswith(run.server.url):
        driver.get(run.server.url)
    if run.thread.ident is None:
        run.thread.start()
    wait_for(lambda: driver.execute_script(
        "return window.triaxcal && window.triaxcal.state && window.triaxcal.state.status")
        == "finished", 600, "the end of the capture")
    run.thread.join(60)
    return run


def page_numbers(d: Any) -> list[tuple[str, str, str]]:
    return d.execute_script(
        "return Array.from(document.querySelectorAll('[data-key]'))"
        ".map(e => [e.dataset.key, e.dataset.value, e.textContent])")


def page_value(d: Any, key: str) -> float | None:
    v = d.execute_script(
        "const e = document.querySelector(`[data-key=\"${arguments[0]}\"]`);"
        "return e ? e.dataset.value : null;", key)
    return None if v in (None, "") else float(v)


def lookup(doc: dict, key: str) -> Any:
    cur: Any = doc
    for part in key.split("."):
        cur = cur[int(part)] if isinstance(cur, list) else cur[part]
    return cur


def png_stats(png: bytes) -> tuple[float, int]:
    """(fraction of non-white pixels, number of distinct colours) of a PNG."""
    from matplotlib.image import imread

    img = imread(io.BytesIO(png), format="png")[..., :3]
    nonwhite = float(np.mean(np.any(img < 0.97, axis=-1)))
    colours = len(np.unique((img * 255).astype(np.uint8).reshape(-1, 3), axis=0))
    return nonwhite, colours


# --------------------------------------------------------------------------------- tests


def test_page_loads_and_waits_for_data(driver, run):
    driver.get(run.server.url)
    wait_for(lambda: driver.execute_script("return window.triaxcal && window.triaxcal.applied"),
             120, "the first state on the page")
    assert driver.execute_script("return typeof Plotly") == "object"
    assert "Waiting for data" in driver.find_element("id", "next").text


def test_coverage_rises_and_the_3d_view_renders(driver, run):
    run.thread.start()  # the board starts streaming now that the page is up
    wait_for(lambda: (page_value(driver, "sensors.accel.quality.0.value") or 0) >= 3, 300,
             "three still poses on the page")
    wait_for(lambda: driver.execute_script(
        "return window.triaxcal.draws.accel > 0 && window.triaxcal.draws.mag > 0"), 300,
        "both 3D views drawn")
    assert driver.execute_script(
        "return document.querySelectorAll('#card-accel .plot3d .gl-container').length") > 0
    # the magnetometer's view fills with points as they arrive: a real picture, not a blank
    plot = driver.find_element("css selector", "#card-mag .plot3d")
    nonwhite, colours = wait_for(
        lambda: (lambda st: st if st[0] > 0.05 and st[1] > 50 else None)(
            png_stats(plot.screenshot_as_png)), 300, "a drawn 3D view", every=1.0)
    assert nonwhite > 0.05 and colours > 50
    # the states the page showed while capturing: the sphere filled as the board turned
    wait_for(lambda: driver.execute_script(
        "return window.triaxcal.state.status") == "finished", 600, "the end of the capture")
    seen = driver.execute_script("return window.triaxcal.seen")
    during = [(poses, cov) for _, status, poses, cov in seen if status == "capturing"]
    assert len(during) >= 5, seen[:20]
    covs = [cov for _, cov in during]
    # (directions are those calibrated by the fit of the moment, so a refit can move a pose
    # to a neighbouring cell: coverage need not rise at every step, but it rises)
    assert covs[0] < 30 and covs[-1] >= covs[0] + 30, covs
    assert during[-1][0] > during[0][0]


@pytest.mark.usefixtures("finished")
def test_fit_converges_to_the_simulators_truth(driver, run):
    assert run.error is None and run.result.stopped_by == "stop"
    doc = run.api()
    truth = {"accel": run.imu.truth.accel, "mag": run.imu.truth.mag}
    cells = {"diag_x": (0, 0), "diag_y": (1, 1), "diag_z": (2, 2), "offdiag_xy": (0, 1),
             "offdiag_xz": (0, 2), "offdiag_yz": (1, 2)}
    for sensor, tr in truth.items():
        fit = doc["sensors"][sensor]["fit"]
        assert fit["source"] == "session" and fit["model"] == "full"
        for i, a in enumerate("xyz"):
            shown = page_value(driver, f"sensors.{sensor}.fit.offset.{i}")
            se = page_value(driver, f"sensors.{sensor}.fit.stderr.offset_{a}")
            assert abs(shown - tr.offset[i]) <= 4 * se, (sensor, a, shown, tr.offset[i], se)
        for name, (i, j) in cells.items():
            shown = page_value(driver, f"sensors.{sensor}.fit.matrix.{i}.{j}")
            se = fit["stderr"][name]
            assert abs(shown - tr.matrix[i, j]) <= 4 * se, (sensor, name, shown, se)
        assert doc["sensors"][sensor]["ready"], doc["sensors"][sensor]["quality"]
    assert doc["stream"]["dropped"] == 0


@pytest.mark.usefixtures("finished")
def test_numbers_on_the_page_equal_api_state(driver, run):
    def differences() -> list[tuple[str, str, Any]]:
        doc = run.api()
        wait_for(lambda: driver.execute_script("return window.triaxcal.version")
                 >= doc["version"], 60, "the page to catch up with /api/state")
        return [(key, value, lookup(doc, key)) for key, value, _ in page_numbers(driver)
                if not key.startswith("stream.records_per_s")  # a rate over the last 2 s
                and (value == "" if lookup(doc, key) is None else float(value))
                != (True if lookup(doc, key) is None else lookup(doc, key))]

    # the page shows the document it was sent; both settle within a refresh once the capture
    # has ended (a number computed at most four times a second may trail by one document)
    wait_for(lambda: differences() == [], 60, "the page's numbers to equal /api/state",
             every=1.0)
    doc = run.api()
    nums = page_numbers(driver)
    assert len(nums) > 60
    checked = 0
    for key, value, text in nums:
        if key.startswith("stream.records_per_s"):
            continue  # a rate over the last two seconds: it moves on its own
        want = lookup(doc, key)
        if want is None:
            assert value == "", key
            continue
        got = float(value)
        assert got == want, (key, got, want)
        # what is written is that number, rounded for display
        shown = float(text.replace(",", "")) if text not in ("-", "") else math.nan
        if key.endswith(".matrix.0.0") or ".matrix." in key:
            continue  # shown scaled by the nominal counts per unit (the column header says)
        assert math.isclose(shown, want, rel_tol=0.05, abs_tol=0.06), (key, text, want)
        checked += 1
    assert checked > 30


@pytest.mark.usefixtures("finished")
def test_screenshot_for_the_readme(driver, run, tmp_path):
    driver.execute_script("window.scrollTo(0, 0)")
    png = driver.get_screenshot_as_png()
    nonwhite, colours = png_stats(png)
    assert nonwhite > 0.2 and colours > 200
    out = (ROOT / "docs" if os.environ.get("TRIAXCAL_UPDATE_SCREENSHOT") == "1"
           else tmp_path) / "live.png"
    out.write_bytes(png)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.usefixtures("finished")
def test_save_writes_what_triaxcal_fit_writes(driver, run, tmp_path, capsys):
    driver.find_element("id", "btnSave").click()
    msg = wait_for(lambda: driver.execute_script(
        "const m = document.getElementById('actionMsg');"
        "return m.classList.contains('ok') || m.classList.contains('err') ? m.textContent : ''"),
        180, "Save to answer")
    assert msg.startswith("\u2713 wrote"), msg
    saved = Calibration.load(run.state.out_dir / "calibration.json")
    ref = tmp_path / "cli.json"
    for cmd in run.api()["fit_commands"]:
        argv = cmd.split()[1:]
        argv[argv.index("-o") + 1] = str(ref)
        assert main(argv) == 0
    cli = Calibration.load(ref)
    assert saved.sensors == cli.sensors == ("accel", "mag")
    for sensor in saved.sensors:
        assert saved.part(sensor).to_dict() == cli.part(sensor).to_dict()


@pytest.mark.usefixtures("finished")
def test_no_console_error_and_no_request_left_127_0_0_1(driver, run):
    errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    assert errors == [], errors
    assert driver.execute_script("return window.triaxcal.errors") == []
    urls = []
    for entry in driver.get_log("performance"):
        msg = json.loads(entry["message"])["message"]
        if msg["method"] == "Network.requestWillBeSent":
            urls.append(msg["params"]["request"]["url"])
    assert any(u.endswith("/api/events") for u in urls)
    assert any(u.endswith("/static/plotly.min.js") for u in urls)
    foreign = [u for u in urls if not u.startswith(("http://127.0.0.1:", "data:", "blob:"))]
    assert foreign == [], foreign


def test_pulled_cable_shows_the_banner_and_capture_resumes(driver, tmp_path):
    r = Run(tmp_path, script=globe_script(hold_s=0.8, seed=SEED), speed=5.0, loop=True,
            mag_radius=None)
    try:
        driver.get(r.server.url)
        r.thread.start()
        wait_for(lambda: (page_value(driver, "samples") or 0) > 500, 240, "data on the page")
        before = page_value(driver, "samples")
        r.dev.unplug(8.0)
        # what the page showed, in order (a loaded machine may answer slower than the cable
        # comes back, so the page keeps the banners it showed)
        shown = wait_for(lambda: [t for k, t in driver.execute_script(
            "return window.triaxcal.banners") if k == "disconnected"], 120,
            "the cable-pulled banner")
        assert "Cable pulled" in shown[0] and "capture resumes by itself" in shown[0]
        wait_for(lambda: [k for k, _ in driver.execute_script(
            "return window.triaxcal.banners")][-1:] == ["reconnected"], 120,
            "the board-is-back banner")
        back = [t for k, t in driver.execute_script("return window.triaxcal.banners")
                if k == "reconnected"]
        assert "The board is back" in back[-1]
        wait_for(lambda: (page_value(driver, "samples") or 0) > before + 300, 120,
                 "records after the reconnect")
        assert page_value(driver, "stream.reconnects") == 1
        assert r.thread.is_alive() and r.error is None
    finally:
        r.close()
    assert r.error is None and r.result is not None and r.result.stats.reconnects == 1
