"""The wearable readers on the real files in shared/realdata/wearables-ggirread (GGIRread and
GGIR test files: an Axivity AX3 and AX6, a GENEActiv 1.1 cut to 64 KB, an ActiGraph wGT3XBT)."""

from __future__ import annotations

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.errors import CalibrationError

pytest.importorskip("skdh")
pytest.importorskip("pygt3x")

from triaxcal.io.wearables import (  # noqa: E402
    geneactiv_header,
    read_geneactiv_pages,
    read_wearable,
)


@pytest.fixture()
def files(realdata):
    return realdata / "wearables-ggirread"


def still_norms(acc, rate, seconds=1.0, sd_g=0.02):
    w = int(rate * seconds)
    nb = len(acc) // w
    x = acc[: nb * w].reshape(nb, w, 3)
    keep = x.std(axis=1).max(axis=1) < sd_g
    return np.linalg.norm(x.mean(axis=1)[keep], axis=1)


def test_axivity_ax3_and_ax6(files):
    ax3 = read_wearable(files / "ax3_testfile.cwa")
    assert ax3.device == "Axivity AX3" and ax3.rate_hz == 100.0
    assert ax3.acc_g.shape == (17400, 3)  # the AX blocks' samples (GGIRread resamples to 17599)
    assert np.mean(np.linalg.norm(ax3.acc_g, axis=1)) == pytest.approx(0.98, abs=0.005)
    assert ax3.time_s[-1] - ax3.time_s[0] == pytest.approx(174, abs=3)
    assert 20 < ax3.temp_c.min() < ax3.temp_c.max() < 35
    ax6 = read_wearable(files / "ax6_testfile.cwa")
    assert ax6.device == "Axivity AX6" and ax6.meta["has_gyro"]
    assert ax6.acc_g.shape == (11320, 3) and ax6.rate_hz == 100.0
    # minutes of handling: no still 10 s window, nothing to calibrate, and it says so
    for rec in (ax3, ax6):
        cal = tc.autocalibrate(rec.acc_g, rec.rate_hz, rec.temp_c)
        assert not cal.accepted and cal.n_still == 0 and "0 still 10 s window" in cal.status


def test_geneactiv_header_pages_and_factory_calibration(files):
    path = files / "GENEActiv_testfile.bin"
    header = geneactiv_header(path)
    assert header["Device Unique Serial Code"] == "012967"
    assert header["Measurement Frequency"] == "85.7 Hz"
    rec = read_wearable(path)
    # the header's Calibration Data: g = (raw * 100 - offset) / gain
    gains, offsets = np.array([25875, 25734, 25538]), np.array([439, -662, -3056])
    assert np.array_equal(rec.factory.offset, offsets / 100)
    assert np.array_equal(rec.factory.diag, 100 / gains)
    # the file is cut (its header says 222,048 pages), so it is not handed to skdh; the page
    # decoder reads its 16 whole pages of 300 samples
    assert "222048 pages" in rec.meta["skdh_refused"] and rec.reader.endswith("page decoder")
    counts, temp, rate, pages = read_geneactiv_pages(path)
    assert pages == 16 and counts.shape == (4800, 3) and rate == 85.7
    assert temp[0] == 21.5 and np.all(temp[:300] == 21.5)
    # page 1 starts with the 12 hex digits 0C4 FFD F3D 004: x 0x0C4, y 0xFFD, z 0xF3D, 12-bit
    assert counts[0].tolist() == [0x0C4, 0xFFD - 4096, 0xF3D - 4096]
    g0 = (counts[0] * 100 - offsets) / gains
    assert np.allclose(rec.acc_g[0], g0, rtol=0, atol=1e-15)
    # the factory calibration in still seconds: 1 g to within 1.5 %
    norms = still_norms(rec.acc_g, rec.rate_hz)
    assert len(norms) >= 5 and np.all(np.abs(norms - 1) < 0.015)
    print(f"\nGENEActiv factory calibration, |a| in still seconds: {np.round(norms, 4)}")
    cal = tc.autocalibrate(rec.acc_g, rec.rate_hz, rec.temp_c)
    assert not cal.accepted and cal.n_windows == 5  # 56 s: far too short for van Hees


def test_actigraph_gt3x(files):
    rec = read_wearable(files / "actigraph_testfile.gt3x")
    assert rec.device == "ActiGraph wGT3XBT" and rec.serial == "MOS2E39180594"
    assert rec.rate_hz == 30.0 and rec.meta["range_g"] == (-8.0, 8.0)
    assert rec.meta["scale"] == 256.0 and rec.meta["firmware"] == "1.9.2"
    assert len(rec) / rec.rate_hz / 60 == pytest.approx(29.5, abs=0.6)  # ~30 min
    # half an hour turned through every side: the method runs (not accepted: < 72 h)
    cal = tc.autocalibrate(rec.acc_g, rec.rate_hz)
    assert cal.sphere_populated and cal.error_after_g < cal.error_before_g
    assert not cal.accepted and "fewer than 72 h" in cal.status
    print(f"\nActiGraph 30 min: {cal}")


def test_bad_files(tmp_path, files):
    with pytest.raises(CalibrationError, match="not found"):
        read_wearable(tmp_path / "none.cwa")
    (tmp_path / "x.edf").write_bytes(b"0")
    with pytest.raises(CalibrationError, match="unknown wearable format"):
        read_wearable(tmp_path / "x.edf")
    (tmp_path / "x.bin").write_text("Device Identity\nDevice Type:Other\n")
    with pytest.raises(CalibrationError, match="not a GENEActiv"):
        read_wearable(tmp_path / "x.bin")
    (tmp_path / "x.cwa").write_bytes(b"MD" + bytes(600))
    with pytest.raises(CalibrationError, match="Axivity"):
        read_wearable(tmp_path / "x.cwa")
    (tmp_path / "x.gt3x").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(CalibrationError, match="ActiGraph"):
        read_wearable(tmp_path / "x.gt3x")
    cut = (files / "GENEActiv_testfile.bin").read_text(encoding="latin-1")[:2500]
    (tmp_path / "cut.bin").write_text(cut, encoding="latin-1")
    with pytest.raises(CalibrationError, match="no complete data page"):
        read_wearable(tmp_path / "cut.bin")


def test_without_the_readers_the_error_names_the_extra(tmp_path, monkeypatch):
    import sys

    (tmp_path / "a.cwa").write_bytes(b"MD" + bytes(100))
    (tmp_path / "a.gt3x").write_bytes(b"PK")
    monkeypatch.setitem(sys.modules, "skdh.io", None)  # import skdh.io now fails
    monkeypatch.setitem(sys.modules, "pygt3x.reader", None)
    for name in ("a.cwa", "a.gt3x"):
        with pytest.raises(CalibrationError, match=r"pip install 'triaxcal\[wearables\]'"):
            read_wearable(tmp_path / name)
