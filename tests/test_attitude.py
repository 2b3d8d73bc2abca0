"""Compass calibration from a flight's attitude (triaxcal.methods.attitude,
triaxcal.calibration.flight) on the simulated flight with truth and the real logs."""

import json

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration.flight import fit_flight, flight_source
from triaxcal.calibration.gate import check_part
from triaxcal.calibration.request import FieldOptions, FitRequest
from triaxcal.sim.flight import write_flight

pytest.importorskip("pymavlink")


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    pytest.importorskip("wmm")
    ef = tc.expected_field(47.37, 8.54, 400.0, date="2026-06-01")
    return write_flight(tmp_path_factory.mktemp("flight"), np.array(ef.vector_ned_ut()) * 10.0)


def test_simulated_flight_recovers_offsets_and_interference(flight):
    req = FitRequest(sensor="mag", method="attitude",
                     field=FieldOptions(location=(47.37, 8.54, 400.0), date="2026-06-01"))
    part, _ = fit_flight(flight["log"], req)
    truth = json.loads(flight["truth"].read_text())
    field = np.linalg.norm(truth["field_mG"])
    assert np.linalg.norm(-part.offset - truth["COMPASS_OFS"]) <= 0.01 * field
    mot = np.asarray(part.stats["interference"]["vector"])
    assert np.linalg.norm(mot - truth["COMPASS_MOT"]) <= 0.05 * np.linalg.norm(truth["COMPASS_MOT"])
    assert check_part(part, "mag").valid
    held = part.stats["attitude"]["held_out"]
    assert held["scatter_after"] * 2 <= held["scatter_before"]
    from triaxcal.export.ardupilot import ardupilot_params

    params = ardupilot_params(tc.Calibration(mag=part))
    assert params["COMPASS_MOTCT"] == 2.0
    assert abs(params["COMPASS_MOT_Z"] - truth["COMPASS_MOT"][2]) < 0.25


@pytest.mark.parametrize("name", ["PXFv2.0b+Rpi.BIN", "Erle-Brain3.BIN"])
def test_real_ardupilot_logs_are_refused_with_the_reason(realdata, name):
    ERLE = realdata / "ardupilot-erle-logs"
    part, _ = fit_flight(ERLE / name, FitRequest(sensor="mag", method="attitude"))
    v = check_part(part, "mag")
    assert not v.valid
    assert any("does not determine" in r or "does not hold still" in r for r in v.reasons)


def test_log_without_attitude_is_refused(tmp_path):
    table = tmp_path / "mag.csv"
    table.write_text("mx,my,mz\n" + "\n".join(f"{i},{-i},{i * 2}" for i in range(50)))
    with pytest.raises(tc.CalibrationError, match="flight log|attitude"):
        tc.fit_session(table, FitRequest(sensor="mag", method="attitude"))


# --------------------------------------------------------------------------------------------
# the same flight as a PX4 ULog, ArduPilot's trim, the yaw rule, the unknown field, the advice

REQ_ZURICH = dict(sensor="mag", method="attitude",
                  field=FieldOptions(location=(47.37, 8.54, 400.0), date="2026-06-01"))


def _recovery(part, truth, scale=1.0):
    """COMPASS_OFS error (% of the field) and COMPASS_MOT error (% of |COMPASS_MOT|)."""
    field = np.linalg.norm(truth["field_mG"])
    ofs = -np.asarray(part.offset) * scale
    mot = np.asarray(part.stats["interference"]["vector"]) * scale
    return (100 * np.linalg.norm(ofs - truth["COMPASS_OFS"]) / field,
            100 * np.linalg.norm(mot - truth["COMPASS_MOT"]) / np.linalg.norm(truth["COMPASS_MOT"]))


def test_simulated_ulog_is_a_ulog_pyulog_reads_and_the_fit_recovers_the_truth(flight):
    pyulog = pytest.importorskip("pyulog")
    ulog = pyulog.ULog(str(flight["ulog"]))
    topics = {d.name: d.data for d in ulog.data_list}
    assert {"vehicle_magnetometer", "vehicle_attitude", "battery_status", "sensor_combined",
            "actuator_controls_0", "vehicle_gps_position"} <= set(topics)
    assert ulog.initial_parameters["EKF2_MAG_TYPE"] == 5
    assert ulog.msg_info_dict["ver_sw_release"] >> 16 == 0x010E       # v1.14
    # the same readings as the DataFlash log's MAG, in gauss
    bin_raw = tc.read_log(flight["log"]).mag.data
    np.testing.assert_allclose(topics["vehicle_magnetometer"]["magnetometer_ga[0]"] * 1000,
                               bin_raw[:, 0], atol=1e-3)
    part, src = fit_flight(flight["ulog"], FitRequest(**REQ_ZURICH))
    assert src.recording.format == "px4-ulog" and part.unit == "gauss"
    assert src.x_per == "A" and src.x_name == "battery_status.current_a"
    assert part.stats["attitude"]["heading"] == "attitude"     # EKF2_MAG_TYPE = 5
    ofs_pct, mot_pct = _recovery(part, json.loads(flight["truth"].read_text()), 1000.0)
    assert ofs_pct <= 1.0 and mot_pct <= 5.0
    assert check_part(part, "mag").valid


def test_ulog_writer_round_trips_through_pyulog(tmp_path):
    pyulog = pytest.importorskip("pyulog")
    from triaxcal.sim.ulog import ulog_bytes

    t = np.arange(5, dtype=np.uint64) * 1000 + 10
    q = np.random.default_rng(0).normal(size=(5, 4))
    path = tmp_path / "x.ulg"
    path.write_bytes(ulog_bytes(
        {"vehicle_attitude": ([("uint64_t", "timestamp"), ("float[4]", "q")],
                              {"timestamp": t, "q": q}),
         "battery_status": ([("uint64_t", "timestamp"), ("float", "current_a"),
                             ("uint8_t", "id")],
                            {"timestamp": t + 1, "current_a": np.arange(5.0),
                             "id": np.ones(5)})},
        start_us=3, info={"sys_name": "PX4", "ver_sw_release": 7}, params={"A": 2, "B": 0.5}))
    u = pyulog.ULog(str(path))
    d = {x.name: x.data for x in u.data_list}
    np.testing.assert_array_equal(d["vehicle_attitude"]["timestamp"], t)
    np.testing.assert_allclose(d["vehicle_attitude"]["q[2]"], q[:, 2].astype(np.float32))
    np.testing.assert_array_equal(d["battery_status"]["current_a"], np.arange(5.0))
    assert u.initial_parameters == {"A": 2, "B": 0.5} and u.start_timestamp == 3
    assert u.msg_info_dict["sys_name"] == "PX4" and u.msg_info_dict["ver_sw_release"] == 7
    with pytest.raises(tc.CalibrationError, match="first field"):
        ulog_bytes({"x": ([("float", "a")], {"a": np.zeros(2)})}, start_us=0)


def test_ardupilot_trim_is_put_back_into_the_attitude(tmp_path):
    """ATT is the vehicle body's attitude (AHRS_TRIM applied); the compass reads in the
    autopilot's. A 3 deg pitch trim left in moves COMPASS_OFS by 8 % of the field."""
    pytest.importorskip("wmm")
    ef = tc.expected_field(47.37, 8.54, 400.0, date="2026-06-01")
    paths = write_flight(tmp_path, np.array(ef.vector_ned_ut()) * 10.0, trim_deg=(1.0, 3.0),
                         duration_s=300.0)
    part, src = fit_flight(paths["log"], FitRequest(**REQ_ZURICH))
    assert src.trim_deg == pytest.approx((1.0, 3.0), abs=1e-6)
    ofs_pct, mot_pct = _recovery(part, json.loads(paths["truth"].read_text()))
    assert ofs_pct <= 1.0 and mot_pct <= 5.0


def test_unknown_field_holds_the_mean_gain(flight):
    """Without the field, roll and pitch only: the offsets still come out within 1 % of the
    field and the gains' mean is 1 (the field's strength is the readings' own)."""
    from triaxcal.methods.attitude import fit_attitude

    src = flight_source(flight["log"], FitRequest(sensor="mag", method="attitude"))
    truth = json.loads(flight["truth"].read_text())
    fit = fit_attitude(src.raw, src.dcm, x=src.x, heading="free")
    assert fit.field_fitted and "mean_gain" in fit.held
    assert np.trace(fit.matrix) == pytest.approx(3.0)
    field = np.linalg.norm(truth["field_mG"])
    assert np.linalg.norm(-fit.offset - truth["COMPASS_OFS"]) <= 0.01 * field


def test_real_log_without_the_field_keeps_its_gains(realdata):
    """Erle-Brain3 (a level flight, no GPS): holding only the x gain let y and z collapse to
    0.49 and 0.15 (and a yaw-free fit to 0.01-0.05); the mean gain holds them within 0.5..2."""
    part, _ = fit_flight(realdata / "ardupilot-erle-logs" / "Erle-Brain3.BIN",
                         FitRequest(sensor="mag", method="attitude"))
    ev = np.linalg.eigvalsh(part.matrix)
    assert 0.5 <= ev.min() and ev.max() <= 2.0
    assert np.trace(part.matrix) == pytest.approx(3.0)


def _rec(fmt, **params):
    from types import SimpleNamespace

    return SimpleNamespace(format=fmt, params=params)


@pytest.mark.parametrize("fmt, params, instance, fused", [
    ("ardupilot-dataflash", {}, 0, True),
    ("ardupilot-dataflash", {"COMPASS_USE": 1.0}, 0, True),
    ("ardupilot-dataflash", {"COMPASS_USE": 0.0}, 0, False),
    ("ardupilot-dataflash", {"EK3_SRC1_YAW": 2.0}, 0, False),          # GPS
    ("ardupilot-dataflash", {"EK3_SRC1_YAW": 8.0}, 0, False),          # GSF
    ("ardupilot-dataflash", {"EK3_SRC1_YAW": 3.0}, 0, True),           # GPS, compass fallback
    ("ardupilot-dataflash", {"EK3_SRC1_YAW": 2.0, "AHRS_EKF_TYPE": 2.0}, 0, True),  # EKF2
    ("ardupilot-dataflash", {"COMPASS_USE2": 1.0, "COMPASS_PRIMARY": 0.0}, 1, False),
    ("ardupilot-dataflash", {"COMPASS_USE": 0.0, "COMPASS_USE2": 1.0}, 1, True),
    ("px4-ulog", {}, None, True),
    ("px4-ulog", {"EKF2_MAG_TYPE": 5}, None, False),
    ("px4-ulog", {"SYS_HAS_MAG": 0}, None, False),
    ("px4-ulog", {"EKF2_GPS_CTRL": 15}, None, False),                  # dual-antenna yaw
    ("px4-ulog", {"EKF2_AID_MASK": 1}, None, True),
])
def test_yaw_is_used_only_when_the_parameters_say_it_is_not_this_compass(fmt, params, instance,
                                                                          fused):
    from triaxcal.calibration.flight import _yaw_from_compass

    used, why = _yaw_from_compass(_rec(fmt, **params), instance or 0)
    assert used is fused and why


def test_a_fused_yaw_is_not_used_however_far_it_strays(realdata):
    """Erle-Brain3's EKF fused the compass (COMPASS_USE = 1) and learned offsets in flight
    (EK2_MAG_CAL = 3): its yaw strays 14 deg RMS from the logged compass heading but still
    carries the compass's errors, so only roll and pitch are used."""
    part, _ = fit_flight(realdata / "ardupilot-erle-logs" / "Erle-Brain3.BIN",
                         FitRequest(sensor="mag", method="attitude"))
    a = part.stats["attitude"]
    assert a["heading"] == "free" and "COMPASS_USE = 1" in a["heading_reason"]
    assert 10 < a["logged_heading_error_deg"] < 20


def test_refused_flight_says_what_to_fly(realdata, tmp_path):
    from triaxcal.calibration.gate import RECORD_INSTEAD, InvalidCalibrationError, require_valid

    part, _ = fit_flight(realdata / "ardupilot-erle-logs" / "Erle-Brain3.BIN",
                         FitRequest(sensor="mag", method="attitude"))
    v = check_part(part, "mag")
    assert not v.valid and v.record_instead != RECORD_INSTEAD["mag"]
    for words in ("full, slow turns", "vary the throttle", "--location", "EK3_SRC1_YAW"):
        assert words in v.record_instead
    assert v.record_instead in v.text()
    # it travels with the part: stored, loaded, and said again by every exporter's gate
    path = tmp_path / "cal.json"
    tc.Calibration(mag=part).save(path)
    loaded = tc.Calibration.load(path).mag
    with pytest.raises(InvalidCalibrationError, match="--location"):
        require_valid(loaded, "mag")


def test_demo_flight_writes_both_logs_and_the_fit_recovers_the_truth(tmp_path, capsys):
    """``triaxcal demo --flight --out-dir DIR``: the logs' own GPS gives the place, today the
    date; COMPASS_OFS within 1 % of the field and COMPASS_MOT within 5 %, from both logs."""
    pytest.importorskip("wmm")
    pytest.importorskip("pyulog")
    from triaxcal.cli import main

    assert main(["demo", "--flight", "--out-dir", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    for name in ("flight.BIN", "flight.ulg", "flight_truth.json"):
        assert (tmp_path / name).is_file() and name in printed
    truth = json.loads((tmp_path / "flight_truth.json").read_text())
    assert truth["COMPASS_MOT_unit"] == "mG per A" and truth["field_date"]
    for name, scale in (("flight.BIN", 1.0), ("flight.ulg", 1000.0)):
        part, _ = fit_flight(tmp_path / name, FitRequest(sensor="mag", method="attitude"))
        assert "GPS" in part.stats["attitude"]["field"] or "gps" in part.stats["attitude"]["field"]
        ofs_pct, mot_pct = _recovery(part, truth, scale)
        assert ofs_pct <= 1.0 and mot_pct <= 5.0, (name, ofs_pct, mot_pct)


def test_exports_through_the_autopilots_equations_give_the_earths_field_back(flight):
    """The fits of the simulated flight, exported (ArduPilot from the DataFlash log, PX4 from
    the ULog) and applied to the logged raw readings and current with each autopilot's own
    equation, turn back into the Earth's field: the field error RMS is the noise's (2 mG per
    axis, 0.3 deg of attitude), against 111 mG uncalibrated."""
    from triaxcal.export.ardupilot import ardupilot_params
    from triaxcal.export.px4 import px4_params

    truth = json.loads(flight["truth"].read_text())
    b = np.asarray(truth["field_mG"])
    # ArduPilot AP_Compass_Backend::correct_field: M ((raw + OFS) * SCALE) + MOT * current
    part, src = fit_flight(flight["log"], FitRequest(**REQ_ZURICH))
    p = {k: float(np.float32(v)) for k, v in ardupilot_params(tc.Calibration(mag=part)).items()}
    m = np.array([[p["COMPASS_DIA_X"], p["COMPASS_ODI_X"], p["COMPASS_ODI_Y"]],
                  [p["COMPASS_ODI_X"], p["COMPASS_DIA_Y"], p["COMPASS_ODI_Z"]],
                  [p["COMPASS_ODI_Y"], p["COMPASS_ODI_Z"], p["COMPASS_DIA_Z"]]])
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in "XYZ"])
    mot = np.array([p[f"COMPASS_MOT_{a}"] for a in "XYZ"])
    scale = p["COMPASS_SCALE"] if 0.85 <= p["COMPASS_SCALE"] <= 1.4 else 1.0
    assert p["COMPASS_MOTCT"] == 2.0
    ap = ((src.raw + ofs) * scale) @ m.T + src.x[:, None] * mot
    expected = np.einsum("nji,j->ni", src.dcm, b)
    err = np.sqrt((np.linalg.norm(ap - expected, axis=1) ** 2).mean())
    raw_err = np.sqrt((np.linalg.norm(src.raw - expected, axis=1) ** 2).mean())
    assert err < 6.0 and raw_err > 100.0
    # PX4 Magnetometer::Correct: S ((raw + power * COMP) - OFF), power = current_a * 0.001 (kA)
    part, src = fit_flight(flight["ulog"], FitRequest(**REQ_ZURICH))
    q = {name: v for name, v, _ in px4_params(tc.Calibration(mag=part))}
    assert q["CAL_MAG_COMP_TYP"] == 2.0 and q["CAL_MAG0_ID"] == 396825
    s = np.array([[q["CAL_MAG0_XSCALE"], q["CAL_MAG0_XODIAG"], q["CAL_MAG0_YODIAG"]],
                  [q["CAL_MAG0_XODIAG"], q["CAL_MAG0_YSCALE"], q["CAL_MAG0_ZODIAG"]],
                  [q["CAL_MAG0_YODIAG"], q["CAL_MAG0_ZODIAG"], q["CAL_MAG0_ZSCALE"]]])
    comp = np.array([q[f"CAL_MAG0_{a}COMP"] for a in "XYZ"])
    off = np.array([q[f"CAL_MAG0_{a}OFF"] for a in "XYZ"])
    px4 = ((src.raw + (src.x * 0.001)[:, None] * comp) - off) @ s.T * 1000.0   # gauss -> mG
    err = np.sqrt((np.linalg.norm(px4 - expected, axis=1) ** 2).mean())
    assert err < 6.0


def test_report_of_a_flight_calibration_draws_the_held_out_check(flight, tmp_path, capsys):
    """``triaxcal report CAL.json --plot`` finds the log by the part's source path, checks its
    SHA-256, and shows the held-out field and heading errors before and after, with a figure."""
    pytest.importorskip("matplotlib")
    from triaxcal.cli import main

    cal = tmp_path / "cal.json"
    args = ["--sensor", "mag", "--method", "attitude", "--location", "47.37,8.54,400",
            "--date", "2026-06-01"]
    assert main(["fit", str(flight["log"]), *args, "-o", str(cal)]) == 0
    part = tc.Calibration.load(cal).mag
    held = part.stats["attitude"]["held_out"]
    capsys.readouterr()
    fig, numbers = tmp_path / "fig.png", tmp_path / "r.json"
    assert main(["report", str(cal), "--plot", str(fig), "-o", str(numbers)]) == 0
    out = capsys.readouterr().out
    assert "held-out check" in out and "heading error RMS" in out
    assert fig.is_file() and fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rep = json.loads(numbers.read_text())["mag"]
    # the figure's numbers are the fit's own held-out numbers, recomputed from the log
    assert rep["error_after_rms"] == pytest.approx(held["field_error_rms_after"], rel=1e-9)
    assert rep["error_before_rms"] == pytest.approx(held["field_error_rms_before"], rel=1e-9)
    assert rep["heading_after_rms"] == pytest.approx(held["heading_rms_deg_after"], rel=1e-9)
    assert rep["error_after_rms"] < 0.1 * rep["error_before_rms"]
    # a log that changed since the fit is not silently judged
    changed = tmp_path / "flight.BIN"
    changed.write_bytes(flight["log"].read_bytes() + b"\0")
    part2 = part.replace(source=str(changed))
    tc.Calibration(mag=part2).save(tmp_path / "cal2.json")
    capsys.readouterr()
    assert main(["report", str(tmp_path / "cal2.json")]) != 0
    assert "SHA-256" in capsys.readouterr().err
