"""The live page: one refit-and-publish cycle against numpy/scipy, and a 60 s capture of a
1000-records-per-second stream with the page open in a headless Chromium.

Run: ``python benches/bench_live.py`` (``--quick``: 15 s capture, fewer rounds;
``--no-browser``: the capture part without the page open; ``--seconds S``).

1. **Cycle.** A :class:`~triaxcal.live.LiveState` holding 84 accelerometer poses (the globe
   scheme, counts) and a full 650-sample magnetometer buffer is refreshed with ``force=True``:
   both sensors refitted exactly as ``triaxcal fit`` does (model chosen by BIC among sphere,
   axis and full; 2-sigma outlier rejection, iterated), MotionCal's numbers, coverage, the
   biggest empty cap, the JSON document and point sets published. The baseline is the same
   cycle with the fits done by ``scipy.optimize.least_squares`` (Levenberg-Marquardt,
   analytic Jacobian, standard errors from ``J^T J``) and numpy, same procedure. Both are timed
   alternately; best of several rounds; the fits alone are timed too.
2. **Capture.** The simulated board runs in another process (100 Hz sampling at speed 10:
   1000 framed records a second); this process captures it through ``SerialReader`` and
   ``capture`` with the live state and server, and a headless Chromium shows the page.
   Reported: frames sent and rows written (dropped = their difference plus damaged frames),
   state updates the page applied per second and 3D redraws per second, the capture process's
   CPU (percent of one core) and resident memory at the start, end and peak, and the same for
   a plain capture without the page.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import resource
import shutil
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import triaxcal as tc
from triaxcal.capture.run import capture, channel_names
from triaxcal.io.serial import Record, SerialReader
from triaxcal.live import LiveOptions, LiveState
from triaxcal.live.quality import SpreadBuffer
from triaxcal.live.state import _Fit
from triaxcal.sim import SimIMU, globe_script

NAMES = channel_names("framed", 10)
#: Headless Chromium without a GPU: WebGL through SwiftShader, the rest of the page rastered by
#: the CPU (SwiftShader rasterising the page itself costs far more than Skia does).
BROWSER_FLAGS = ["--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-gpu-rasterization", "--disable-accelerated-2d-canvas",
                 "--window-size=1400,1400", "--no-first-run", "--disable-extensions"]
N_PARAMS = {"sphere": 4, "axis": 6, "full": 9}


# ------------------------------------------------------------- the scipy/numpy baseline


def _unpack(model: str, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    o = th[:3]
    if model == "sphere":
        return o, np.eye(3) * th[3]
    if model == "axis":
        return o, np.diag(th[3:6])
    return o, np.array([[th[3], th[6], th[7]], [th[6], th[4], th[8]], [th[7], th[8], th[5]]])


def scipy_fit(p: np.ndarray, model: str, radius: float) -> dict[str, Any]:
    """Geometric fit ``|W (p - o)| = radius`` by least_squares(method="lm"), analytic
    Jacobian; standard errors from the Jacobian at the solution."""
    from scipy.optimize import least_squares

    def resid(th: np.ndarray) -> np.ndarray:
        o, w = _unpack(model, th)
        return np.linalg.norm((p - o) @ w.T, axis=1) - radius

    def jac(th: np.ndarray) -> np.ndarray:
        o, w = _unpack(model, th)
        u = p - o
        v = u @ w.T
        n = np.linalg.norm(v, axis=1)[:, None]
        cols = [-(v @ w) / n]
        if model == "sphere":
            cols.append((v * u).sum(axis=1, keepdims=True) / n)
        else:
            cols.append(v * u / n)
            if model == "full":
                cols.append(np.column_stack([
                    v[:, 0] * u[:, 1] + v[:, 1] * u[:, 0], v[:, 0] * u[:, 2] + v[:, 2] * u[:, 0],
                    v[:, 1] * u[:, 2] + v[:, 2] * u[:, 1]]) / n)
        return np.hstack(cols)

    c = p.mean(axis=0)
    s = radius / np.mean(np.linalg.norm(p - c, axis=1))
    x0 = {"sphere": np.r_[c, s], "axis": np.r_[c, s, s, s],
          "full": np.r_[c, s, s, s, 0, 0, 0]}[model]
    r = least_squares(resid, x0, jac=jac, method="lm")
    o, w = _unpack(model, r.x)
    res = r.fun
    dof = max(len(p) - len(x0), 1)
    cov = np.linalg.pinv(r.jac.T @ r.jac) * float(res @ res) / dof
    return {"model": model, "offset": o, "matrix": w, "rms": float(np.sqrt(np.mean(res**2))),
            "stderr": np.sqrt(np.abs(np.diag(cov))), "n": len(p)}


def scipy_robust(p: np.ndarray, radius: float, sigma: float = 2.0,
                 rounds: int = 10) -> tuple[dict[str, Any], np.ndarray]:
    """fit_robust(model="auto")'s procedure with scipy fits: BIC among the three models on
    the relative residuals, refit after rejecting lengths beyond ``sigma``, until stable."""
    def auto(q: np.ndarray) -> dict[str, Any]:
        best, score = None, math.inf
        for m in ("sphere", "axis", "full"):
            f = scipy_fit(q, m, radius)
            rel = np.linalg.norm((q - f["offset"]) @ f["matrix"].T, axis=1) / radius - 1
            bic = len(q) * math.log(max(float(rel @ rel), 1e-300) / len(q)) + \
                N_PARAMS[m] * math.log(len(q))
            if bic < score:
                best, score = f, bic
        assert best is not None
        return best

    keep = np.ones(len(p), dtype=bool)
    fit = auto(p)
    for _ in range(rounds):
        norms = np.linalg.norm((p - fit["offset"]) @ fit["matrix"].T, axis=1)
        new = np.abs(norms - norms.mean()) <= sigma * norms.std(ddof=1)
        if np.array_equal(new, keep):
            break
        keep = new
        fit = auto(p[keep])
    return fit, np.flatnonzero(~keep)


class ScipyLiveState(LiveState):
    """The same live cycle with the fits done by scipy/numpy."""

    def _fit_live(self, sensor: str, pts: np.ndarray) -> _Fit:
        radius = self.accel_radius if sensor == "accel" else float(self.mag_radius or 1.0)
        f, rejected = scipy_robust(pts, radius, self.options.sigma, self.options.rounds)
        names = {"sphere": ["data_radius"], "axis": ["diag_x", "diag_y", "diag_z"],
                 "full": ["diag_x", "diag_y", "diag_z", "offdiag_xy", "offdiag_xz",
                          "offdiag_yz"]}[f["model"]]
        se = dict(zip(["offset_x", "offset_y", "offset_z", *names], map(float, f["stderr"])))
        return _Fit(model=f["model"], offset=f["offset"], matrix=f["matrix"], radius=radius,
                    rms=f["rms"], stderr=se, n=f["n"], rejected=list(map(int, rejected)),
                    converged=True, condition=None, reason=None, source="live",
                    unit=self.accel_unit if sensor == "accel" else self.mag_unit)


# ---------------------------------------------------------------------- 1. the cycle


def loaded_state(cls: type, seed: int = 3) -> LiveState:
    """A live state with 84 accelerometer poses and a full 650-sample magnetometer buffer."""
    imu = SimIMU(seed)
    rec = imu.record(globe_script(hold_s=1.0, seed=seed), 100.0)
    frames = rec.frames(10).astype(float)
    st = cls(Path(tempfile.mkdtemp()) / "s.csv", NAMES,
             options=LiveOptions(mag_radius=f"{imu.truth.field_ut:g}uT"))
    # the 84 poses of the globe scheme: the mean of each still hold
    st._poses = [frames[rec.still & (rec.pose == j)].mean(axis=0)
                 for j in range(int(rec.pose.max()) + 1)]
    # the magnetometer tumbling through every direction: fill the buffer to its 650
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(20_000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    truth = imu.truth.mag
    raw = truth.offset + (u * imu.truth.field_ut) @ np.linalg.inv(truth.matrix).T
    raw += rng.normal(0, 3.0, raw.shape)
    buf = SpreadBuffer(650)
    for i in range(0, len(raw), 50):
        buf.add(raw[i:i + 50])
    st._magbuf = buf
    st.on_records([Record(0.0, tuple(frames[-1].astype(int)))])
    return st


def bench_cycle(rounds: int) -> None:
    ours, base = loaded_state(LiveState), loaded_state(ScipyLiveState)
    print(f"cycle data: {len(ours._poses)} accelerometer poses, {len(ours._magbuf)} "
          "magnetometer samples")
    t_ours, t_base, f_ours, f_base = [], [], [], []
    acc = ours._poses and np.array(ours._poses)[:, :3]
    mag = ours._magbuf.points
    for _ in range(rounds):
        for st, times in ((ours, t_ours), (base, t_base)):
            t0 = time.perf_counter()
            st.refresh(force=True)
            times.append(time.perf_counter() - t0)
        for st, times in ((ours, f_ours), (base, f_base)):
            t0 = time.perf_counter()
            st._fit_live("accel", acc)
            st._fit_live("mag", mag)
            times.append(time.perf_counter() - t0)
    a, b = ours.document()["sensors"], base.document()["sensors"]
    for s in ("accel", "mag"):
        d = np.abs(np.array(a[s]["fit"]["offset"]) - np.array(b[s]["fit"]["offset"])).max()
        se = max(a[s]["fit"]["stderr"][f"offset_{x}"] for x in "xyz")
        print(f"  {s}: model {a[s]['fit']['model']} vs {b[s]['fit']['model']}, offsets differ "
              f"by {d:.3g} counts ({d / se:.2g} standard errors)")
    to, tb = min(t_ours), min(t_base)
    fo, fb = min(f_ours), min(f_base)
    print(f"{'refit-and-publish cycle':<34} triaxcal {to * 1e3:8.2f} ms   numpy/scipy "
          f"{tb * 1e3:8.2f} ms   {tb / to:5.1f}x")
    print(f"{'  of which the two robust fits':<34} triaxcal {fo * 1e3:8.2f} ms   numpy/scipy "
          f"{fb * 1e3:8.2f} ms   {fb / fo:5.1f}x")
    print(f"  (best of {rounds}; the rest of the cycle -- MotionCal numbers, coverage, empty "
          "caps, JSON -- is the same code in both)")


# ---------------------------------------------------------------------- 2. the capture


def _device(link: str, speed: float, conn: Any, quiet: Any, close: Any) -> None:
    from triaxcal.sim import SimDevice

    imu = SimIMU(5)
    with SimDevice(imu, globe_script(hold_s=1.0, seed=5), rate_hz=100.0, speed=speed,
                   loop=True, seed=5, link=link) as dev:
        conn.send(dev.port)
        quiet.wait()
        dev.silence(1e6)  # stop streaming; what is queued still goes out
        time.sleep(1.0)
        sent = list(dev.sent)
        conn.send((len(sent), sum(1 for f in sent if f.intact)))
        close.wait(60)


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _browser() -> Any:
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if not (chromium and driver):
        raise SystemExit("the capture part needs chromium and chromedriver (make deps)")
    o = Options()
    o.binary_location = chromium
    for a in BROWSER_FLAGS:
        o.add_argument(a)
    d = webdriver.Chrome(options=o, service=Service(driver))
    d.set_page_load_timeout(240)
    d.set_script_timeout(120)
    return d


def bench_capture(seconds: float, page: bool, live: bool = True) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp())
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    quiet_dev, close_dev = ctx.Event(), ctx.Event()
    proc = ctx.Process(target=_device, args=(str(tmp / "ttySIM0"), 10.0, child, quiet_dev,
                                             close_dev))
    proc.start()
    port = parent.recv()
    reader = SerialReader(port, protocol="framed", channels=10)
    session = tmp / "session.csv"
    state = server = drv = None
    if live:
        from triaxcal.live.server import LiveServer

        state = LiveState(session, NAMES, port=port, options=LiveOptions(mag_radius="50uT"))
        state.attach(reader)
        server = LiveServer(state, port=0).start()
        state.start()
    if page and server is not None:
        drv = _browser()
        drv.get(server.url)
    stop = threading.Event()
    out: dict[str, Any] = {}

    def run() -> None:
        out["result"] = capture(reader, session, stop=stop, progress=None, bell=False,
                                handle_sigint=False,
                                on_records=state.on_records if state is not None else None)

    rss0 = _rss_mib()
    th = threading.Thread(target=run)
    th.start()
    time.sleep(3.0)  # warm up: the stream runs, the page has drawn
    js = "return [window.triaxcal.applied, window.triaxcal.messages, " \
         "window.triaxcal.draws.accel + window.triaxcal.draws.mag, window.triaxcal.painted]"
    p0 = drv.execute_script(js) if drv else None
    c0, w0, rows0 = time.process_time(), time.monotonic(), None
    if state is not None:
        rows0 = state.rows
    rss_samples = []
    while time.monotonic() - w0 < seconds:
        time.sleep(1.0)
        rss_samples.append(_rss_mib())
    c1, w1 = time.process_time(), time.monotonic()
    p1 = drv.execute_script(js) if drv else None
    rows1 = state.rows if state is not None else None
    quiet_dev.set()  # the board stops streaming; the capture reads what is on its way
    sent, intact = parent.recv()
    stop.set()
    th.join(60)
    close_dev.set()
    proc.join(30)
    res = out["result"]
    if drv is not None:
        drv.quit()
    if state is not None and server is not None:
        doc = json.load(urllib.request.urlopen(server.url + "api/state", timeout=30))
        out["refit_ms"] = doc["timing"]["refit_ms"]
        state.stop()
        server.stop()
    wall = w1 - w0
    out.update(
        wall=wall, cpu_pct=100.0 * (c1 - c0) / wall, rows=res.samples, sent=sent,
        intact=intact, dropped=res.stats.dropped,
        cleared=intact - res.samples - res.stats.dropped,
        rate=(rows1 - rows0) / wall if rows0 is not None and rows1 is not None else None,
        rss0=rss0, rss1=rss_samples[-1] if rss_samples else _rss_mib(),
        rss_max=max(rss_samples) if rss_samples else None,
        peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    )
    if p0 is not None and p1 is not None:
        out["applied_per_s"] = (p1[0] - p0[0]) / wall
        out["messages_per_s"] = (p1[1] - p0[1]) / wall
        out["draws_per_s"] = (p1[2] - p0[2]) / wall
        out["painted_per_s"] = (p1[3] - p0[3]) / wall
    shutil.rmtree(tmp, ignore_errors=True)
    return out


def print_capture(name: str, r: dict[str, Any]) -> None:
    print(f"{name}: {r['wall']:.0f} s measured, {r['rows']:,} rows written of {r['sent']:,} "
          f"frames sent ({r['intact']:,} intact): dropped {r['dropped']} (damaged or missing "
          f"by sequence number); {r['cleared']} sent before the reader switched the board on "
          "and cleared its input (by design); records/s "
          f"{r['rate'] if r['rate'] is not None else r['rows'] / r['wall']:.0f}")
    print(f"  capture process CPU {r['cpu_pct']:.0f} % of one core (device simulated in another "
          f"process); RSS {r['rss0']:.0f} MiB at start, {r['rss1']:.0f} MiB at the end "
          f"(max sampled {r['rss_max']:.0f} MiB, process peak {r['peak']:.0f} MiB)")
    if "applied_per_s" in r:
        print(f"  page: {r['applied_per_s']:.1f} state updates/s applied (of "
              f"{r['messages_per_s']:.1f} received), {r['painted_per_s']:.1f} frames/s painted "
              f"with new data, {r['draws_per_s']:.1f} 3D redraws/s; last refit cycle "
              f"{r.get('refit_ms', float('nan')):.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="15 s capture, fewer rounds")
    ap.add_argument("--seconds", type=float, default=None, help="capture length (default 60)")
    ap.add_argument("--no-browser", action="store_true", help="capture without the page open")
    ap.add_argument("--skip-capture", action="store_true", help="only the cycle")
    args = ap.parse_args()
    seconds = args.seconds or (15.0 if args.quick else 60.0)
    print(f"triaxcal {tc.__version__}, numpy {np.__version__}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.1f}")
    bench_cycle(5 if args.quick else 20)
    if args.skip_capture:
        return
    print_capture(f"capture with the live page{' (no browser)' if args.no_browser else ''}",
                  bench_capture(seconds, page=not args.no_browser))
    print_capture("plain capture, no live page",
                  bench_capture(min(seconds, 20.0), page=False, live=False))


if __name__ == "__main__":
    sys.exit(main())
