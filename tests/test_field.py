"""The expected field from the World Magnetic Model: the WMM2025 report's test values, the
extra, and hostile places, dates and files."""

from __future__ import annotations

import sys

import pytest
import triaxcal as tc
from triaxcal.methods import field as fieldmod

# The test-value table of the WMM2025 Technical Report (NOAA NCEI / BGS, December 2024):
# decimal year, height above the WGS 84 ellipsoid (km), geodetic latitude and longitude (deg),
# X, Y, Z, H, F (nT), I, D (deg). The report prints 0.1 nT and 0.01 deg.
WMM2025_TEST_VALUES = [
    (2025.0, 0, 80, 0, 6521.6, 145.9, 54791.5, 6523.2, 55178.5, 83.21, 1.28),
    (2025.0, 0, 0, 120, 39677.8, -109.6, -10580.2, 39677.9, 41064.3, -14.93, -0.16),
    (2025.0, 0, -80, 240, 6117.5, 15751.9, -52022.5, 16898.1, 54698.2, -72.00, 68.78),
    (2025.0, 100, 80, 0, 6216.0, 92.4, 52598.8, 6216.7, 52964.9, 83.26, 0.85),
    (2025.0, 100, 0, 120, 37688.6, -96.2, -10152.1, 37688.7, 39032.1, -15.08, -0.15),
    (2025.0, 100, -80, 240, 5907.6, 14780.3, -49540.7, 15917.1, 52035.0, -72.19, 68.21),
    (2027.5, 0, 80, 0, 6500.8, 294.5, 54869.4, 6507.5, 55253.9, 83.24, 2.59),
    (2027.5, 0, 0, 120, 39701.6, -167.4, -10381.8, 39702.0, 41036.9, -14.65, -0.24),
    (2027.5, 0, -80, 240, 6200.7, 15730.3, -51783.7, 16908.3, 54474.2, -71.92, 68.49),
    (2027.5, 100, 80, 0, 6196.7, 233.8, 52670.5, 6201.1, 53034.3, 83.29, 2.16),
    (2027.5, 100, 0, 120, 37711.5, -148.7, -9969.8, 37711.8, 39007.4, -14.81, -0.23),
    (2027.5, 100, -80, 240, 5984.0, 14760.1, -49317.7, 15927.0, 51825.7, -72.10, 67.93),
]
# Half a unit of the last printed digit: a value rounded to 0.1 nT is within 0.05 nT of the
# model's. The 1 % on top allows for the double-precision arithmetic of either implementation.
TOL_NT = 0.05 * 1.01
TOL_DEG = 0.005 * 1.01


def _backends() -> list[str]:
    out = []
    for mod, name in (("wmm", "wmm-calculator"), ("pygeomag", "pygeomag")):
        try:
            __import__(mod)
        except ImportError:
            continue
        out.append(name)
    return out


@pytest.fixture(params=_backends() or ["none"])
def backend(request, monkeypatch):
    if request.param == "none":
        pytest.skip("neither wmm-calculator nor pygeomag is installed (the geo extra)")
    if request.param == "pygeomag":
        monkeypatch.setitem(sys.modules, "wmm", None)  # import wmm -> ImportError
    return request.param


def test_wmm2025_report_test_values(backend):
    worst = {"nT": 0.0, "deg": 0.0}
    for yr, alt_km, lat, lon, x, y, z, h, f, inc, dec in WMM2025_TEST_VALUES:
        e = tc.expected_field(lat, lon, alt_km * 1000.0, date=yr)
        assert e.backend.startswith(backend)
        assert e.model == "WMM2025"
        got = (e.north_ut, e.east_ut, e.down_ut, e.horizontal_ut, e.total_ut)
        for g, want in zip(got, (x, y, z, h, f)):
            worst["nT"] = max(worst["nT"], abs(g * 1000 - want))
            assert abs(g * 1000 - want) <= TOL_NT, (yr, alt_km, lat, lon, g * 1000, want)
        for g, want in ((e.inclination_deg, inc), (e.declination_deg, dec)):
            worst["deg"] = max(worst["deg"], abs(g - want))
            assert abs(g - want) <= TOL_DEG, (yr, alt_km, lat, lon, g, want)
    # the check has teeth: the table's last digit is reached, not merely approached
    assert worst["nT"] > 0.03 and worst["deg"] > 0.003


def test_fields_are_consistent_and_uncertainty_from_the_error_model(backend):
    e = tc.expected_field(47.37, 8.54, 408.0, date="2026-05-17")
    assert e.horizontal_ut == pytest.approx((e.north_ut**2 + e.east_ut**2) ** 0.5)
    assert e.total_ut == pytest.approx((e.horizontal_ut**2 + e.down_ut**2) ** 0.5)
    assert 40 < e.total_ut < 55 and 60 < e.inclination_deg < 67 and 0 < e.declination_deg < 6
    assert e.uncertainty["total_ut"] == pytest.approx(0.138)
    assert e.uncertainty["inclination_deg"] == pytest.approx(0.20)
    # D error: hypot(0.26, 5417 / H[nT]) deg
    assert e.uncertainty["declination_deg"] == pytest.approx(
        (0.26**2 + (5417 / (e.horizontal_ut * 1000)) ** 2) ** 0.5)
    assert e.warnings == ()
    assert "total 48." in e.text() and "inclination 63." in e.text()
    assert fieldmod.ExpectedField.from_dict(e.to_dict()) == e


def test_weak_horizontal_field_is_warned(backend):
    # near the north magnetic pole (the second row of the report's test data set)
    e = tc.expected_field(86.0, 150.0, 0.0, date="2025-06-01")
    assert e.horizontal_ut < 6.0
    assert any("zone" in w for w in e.warnings)


def test_missing_extra_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "wmm", None)
    monkeypatch.setitem(sys.modules, "pygeomag", None)
    with pytest.raises(tc.CalibrationError, match=r"triaxcal\[geo\]"):
        tc.expected_field(10.0, 20.0)


@pytest.mark.parametrize("lat, lon, alt, date, match", [
    (91.0, 0.0, 0.0, "2026-01-01", "latitude"),
    (0.0, -181.0, 0.0, "2026-01-01", "longitude"),
    (0.0, 0.0, -5000.0, "2026-01-01", "altitude"),
    (0.0, 0.0, 0.0, "2013-05-01", "2024-11-13 to 2029-12-31"),
    (0.0, 0.0, 0.0, "2031-01-01", "holds from"),
    (0.0, 0.0, 0.0, "01/05/2026", "YYYY-MM-DD"),
    (float("nan"), 0.0, 0.0, "2026-01-01", "finite"),
    ("north", 0.0, 0.0, "2026-01-01", "number"),
])
def test_bad_places_and_dates(lat, lon, alt, date, match):
    with pytest.raises(tc.CalibrationError, match=match):
        tc.expected_field(lat, lon, alt, date=date)


@pytest.mark.parametrize("text, match", [
    ("47.3", "LAT,LON"), ("47.3,8.5,400,1", "LAT,LON"), ("north,8.5", "latitude"),
    ("47.3,,400", "LAT,LON"), ("95,8", "latitude"), ("47,8,1e9", "altitude"),
])
def test_parse_location_rejects(text, match):
    with pytest.raises(tc.CalibrationError, match=match):
        fieldmod.parse_location(text)


def test_stored_field_is_validated():
    good = {"model": "WMM2025", "backend": "x", "date": "2026-01-01", "decimal_year": 2026.0,
            "lat_deg": 10.0, "lon_deg": 20.0, "alt_m": 0.0, "total_ut": 50.0,
            "horizontal_ut": 30.0, "north_ut": 30.0, "east_ut": 0.0, "down_ut": 40.0,
            "inclination_deg": 53.13, "declination_deg": 0.0}
    assert fieldmod.ExpectedField.from_dict(good).total_ut == 50.0
    for change, match in (({"total_ut": 60.0}, "inconsistent"), ({"lat_deg": 100}, "lat_deg"),
                          ({"date": "yesterday"}, "YYYY-MM-DD"), ({"extra": 1}, "unknown"),
                          ({"total_ut": "50"}, "number"), ({"uncertainty": {"z": 1}}, "unknown"),
                          ({"warnings": "oops"}, "strings")):
        with pytest.raises(tc.CalibrationError, match=match):
            fieldmod.ExpectedField.from_dict({**good, **change})
    bad = dict(good)
    del bad["down_ut"]
    with pytest.raises(tc.CalibrationError, match="lacks"):
        fieldmod.ExpectedField.from_dict(bad)
