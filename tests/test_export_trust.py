"""Trust at the exit: no export, ``send`` or live button lets an invalid calibration out unless
forced (and then the output says so), no export assumes a driver's scale, corrections on top of
an autopilot's calibration are exported as absolute calibrations, Kalibr's YAML reads back as
floats, and C headers refuse what a float or Q7.24 cannot carry."""

from __future__ import annotations

import json
import shutil
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest
import triaxcal as tc
import yaml
from triaxcal.calibration.gate import InvalidCalibrationError
from triaxcal.cli import main
from triaxcal.export import (
    EXPORT_FORMATS,
    adafruit_calib,
    ardupilot_params,
    export,
    kalibr_imu_yaml,
    kalibr_intrinsics,
    px4_params,
)
from triaxcal.io.logs.autopilot import ardupilot_part, px4_part

GCC = shutil.which("gcc")
REASON = "its residual RMS is 28 % of the radius (at most 20 %)"


def _acc(**kw) -> tc.SensorCalibration:
    d = {"offset": [0.1, -0.05, 0.2], "matrix": np.diag([1.01, 0.99, 1.0]), "raw_unit": "m/s^2",
         "unit": "m/s^2", "radius": 9.80665, "model": "axis"}
    d.update(kw)
    return tc.SensorCalibration(**d)


def _gyr(**kw) -> tc.SensorCalibration:
    d = {"offset": [0.01, -0.02, 0.003], "matrix": np.eye(3), "raw_unit": "rad/s",
         "unit": "rad/s"}
    d.update(kw)
    return tc.SensorCalibration(**d)


def _mag(**kw) -> tc.SensorCalibration:
    d = {"offset": [12.0, -3.0, 20.0], "matrix": np.diag([1.02, 0.98, 1.0]), "raw_unit": "uT",
         "unit": "uT", "radius": 48.0, "model": "axis"}
    d.update(kw)
    return tc.SensorCalibration(**d)


def _invalid_cal() -> tc.Calibration:
    """Every part marked as `fit --force` writes a refused fit."""
    bad = {"valid": False, "invalid_reasons": (REASON,)}
    return tc.Calibration(accel=_acc(**bad), gyro=_gyr(**bad), mag=_mag(**bad))


def _options(fmt: str) -> dict:
    if fmt == "kalibr":
        return {"rate_hz": 200.0}
    if fmt == "motioncal":
        return {"offsets_only": True}
    if fmt == "adafruit":  # it holds no accelerometer gains
        return {"sensors": ["mag", "gyro"]}
    return {}


def _read(path, fmt):
    return path.read_bytes() if fmt == "motioncal" else path.read_text()


# ------------------------------------------------------------------------ the gate, every format


@pytest.mark.parametrize("fmt", [f for f in EXPORT_FORMATS if f != "c-fixed"])
def test_every_format_refuses_an_invalid_part_and_marks_it_when_forced(fmt, tmp_path):
    """Before: every format wrote a part marked "valid": false, with exit 0 and no word."""
    cal = _invalid_cal()
    out = tmp_path / f"x.{fmt}"
    with pytest.raises(InvalidCalibrationError, match="not a valid calibration"):
        export(cal, fmt, out, **_options(fmt))
    assert not out.exists()
    export(cal, fmt, out, force=True, **_options(fmt))
    data = _read(out, fmt)
    if fmt == "c":
        assert "NOT A VALID CALIBRATION" in data and REASON in data.replace("\n * ", " ")
        assert "#define TRIAXCAL_CALIBRATION_NOT_VALID 1" in data
    elif fmt in ("js", "js-espruino"):
        assert "// NOT A VALID CALIBRATION" in data and "valid: false" in data
        assert "invalidReasons" in data
    elif fmt == "json":
        back = tc.Calibration.from_json(data)
        assert all(back.part(s).valid is False for s in back.sensors)
        assert back.accel.invalid_reasons == (REASON,)
    elif fmt in ("ardupilot", "px4"):
        head = " ".join(ln[2:] for ln in data.splitlines() if ln.startswith("# "))
        assert "NOT A VALID CALIBRATION" in head and REASON in head
        # wrapped: a loader reading into a short line buffer never sees a comment's tail alone
        assert all(len(ln) <= 90 for ln in data.splitlines() if REASON[:20] in ln)
    elif fmt == "kalibr":
        d = yaml.safe_load(data)
        assert d["valid"] is False and any(REASON in r for r in d["invalid_reasons"])
    elif fmt == "adafruit":
        assert json.loads(data)["valid"] is False
    elif fmt == "motioncal":
        assert len(data) == 68  # a binary packet cannot carry the mark: the CLI says so


def test_fixed_point_header_gated_and_marked():
    part = tc.SensorCalibration(offset=[10, -20, 30], matrix=np.eye(3) / 16384, unit="g",
                                valid=False, invalid_reasons=(REASON,))
    with pytest.raises(tc.CalibrationError, match="not a valid calibration"):
        tc.c_fixed_header(tc.Calibration(accel=part))
    text = tc.c_fixed_header(tc.Calibration(accel=part), force=True)
    assert "NOT A VALID CALIBRATION" in text and "TRIAXCAL_CALIBRATION_NOT_VALID 1" in text


def test_a_part_never_judged_is_judged_at_export():
    """A hand-made part that the gate would refuse (an offset of 2 g) is refused at export
    although nobody marked it."""
    cal = tc.Calibration(accel=_acc(offset=[20.0, 0, 0]))
    assert cal.accel.valid is None
    with pytest.raises(tc.CalibrationError, match="its offset reaches"):
        tc.c_header(cal)
    assert "NOT A VALID" in tc.c_header(cal, force=True)
    tc.c_header(tc.Calibration(accel=_acc()))  # a plausible part passes


@pytest.mark.slow
def test_issue_log_fit_is_refused_then_its_forced_file_refused_at_export(realdata, tmp_path,
                                                                        capsys):
    """The issue's reproduction: the Erle-Brain 3 accelerometer with its calibration undone."""
    log = realdata / "ardupilot-erle-logs" / "Erle-Brain3.BIN"
    ap = tmp_path / "ap.json"
    argv = ["fit", str(log), "--sensor", "accel", "--undo-autopilot-cal", "--radius",
            "9.80665m/s^2", "-o", str(ap)]
    assert main(argv) == 2 and not ap.exists()
    assert main([*argv, "--force"]) == 0
    capsys.readouterr()
    h = tmp_path / "ap.h"
    assert main(["export", str(ap), "--format", "c", "-o", str(h)]) == 2
    err = capsys.readouterr().err
    assert not h.exists() and "not a valid calibration" in err and "--force" in err
    assert main(["export", str(ap), "--format", "c", "-o", str(h), "--force"]) == 0
    out = capsys.readouterr().out
    assert "NOT A VALID CALIBRATION" in out and "NOT A VALID CALIBRATION" in h.read_text()
    if GCC:
        _compile(h, tmp_path)


def test_send_refuses_an_invalid_calibration_before_opening_the_port(tmp_path, capsys):
    path = tmp_path / "cal.json"
    _invalid_cal().save(path)
    argv = ["send", str(path), "--port", "/dev/does-not-exist", "--timeout", "0.2",
            "--offsets-only"]
    assert main(argv) == 2
    assert "refused to send it" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 1  # forced past the gate: now the port is the problem
    assert "cannot open" in capsys.readouterr().err


def _live_state(tmp_path, cal):
    from triaxcal.live import actions
    from triaxcal.live.options import LiveOptions

    state = SimpleNamespace(out_dir=tmp_path, options=LiveOptions(out_dir=tmp_path),
                            last_action=None, _reader=SimpleNamespace(polled=False),
                            status="capturing", protocol="framed", port="loop://")
    path = tmp_path / "calibration.json"
    cal.save(path)
    return state, actions, (lambda st: (cal, path, "saved"))


def test_live_export_and_send_refuse_an_invalid_calibration(tmp_path, monkeypatch):
    state, actions, fake_save = _live_state(tmp_path, _invalid_cal())
    monkeypatch.setattr(actions, "_save", fake_save)
    res = actions.export_header(state, "c")
    assert not res["ok"] and "not a valid calibration" in res["message"]
    assert not (tmp_path / "triaxcal_calibration.h").exists()
    res = actions.export_header(state, "c", force=True)
    assert res["ok"] and "NOT A VALID CALIBRATION" in res["message"]
    assert "NOT A VALID" in (tmp_path / "triaxcal_calibration.h").read_text()
    res = actions.send(state, offsets_only=True)
    assert not res["ok"] and "not a valid calibration" in res["message"]
    assert "refused to send it" in res["message"]


def test_live_send_needs_the_driver_scale(tmp_path, monkeypatch):
    counts = tc.Calibration(accel=tc.SensorCalibration(offset=[10, -20, 30],
                                                       matrix=np.eye(3) / 16384, unit="g"))
    state, actions, fake_save = _live_state(tmp_path, counts)
    monkeypatch.setattr(actions, "_save", fake_save)
    res = actions.send(state, offsets_only=True)
    assert not res["ok"] and "does not guess the driver's scale" in res["message"]
    assert "--counts-per-unit" in res["message"]


# ------------------------------------------------------------------------ no silent scale


def _counts_mag(radius=None) -> tc.Calibration:
    # an ICM-20948 magnetometer fitted in counts (0.15 uT/count: 48 uT ~ 320 counts)
    return tc.Calibration(mag=tc.SensorCalibration(
        offset=[200.0, -150.0, 90.0], matrix=np.diag([1.02, 0.98, 1.0]), raw_unit="counts",
        unit="counts", radius=radius, model="axis"))


@pytest.mark.parametrize("fmt", ["ardupilot", "px4", "adafruit", "motioncal"])
def test_a_part_in_counts_needs_the_driver_scale(fmt, tmp_path, capsys):
    """Before: 10 counts/uT was assumed (COMPASS_DIA about 1.45 for an ICM-20948)."""
    path = tmp_path / "m.json"
    _counts_mag().save(path)
    out = tmp_path / "out"
    extra = ["--mag-field", "48uT"] if fmt == "adafruit" else []
    assert main(["export", str(path), "--format", fmt, "-o", str(out), *extra]) == 1
    err = capsys.readouterr().err
    assert "mag part is in raw counts" in err and "does not guess the driver's scale" in err
    assert "--counts-per-unit mag=" in err and "--sensor-model" in err and not out.exists()
    assert "not determined" not in err
    assert main(["export", str(path), "--format", fmt, "-o", str(out), "--sensor-model",
                 "ICM-20948", *extra]) == 0
    assert out.stat().st_size > 0


def test_sensor_model_gives_the_datasheet_scale_to_ardupilot():
    cal = _counts_mag()
    p = ardupilot_params(cal, sensor_model="ICM-20948")
    # 0.15 uT/count = 1.5 mG/count: offsets in mG, DIA the dimensionless gains
    assert p["COMPASS_OFS_X"] == pytest.approx(-200.0 * 1.5)
    assert p["COMPASS_DIA_X"] * (p["COMPASS_SCALE"] or 1) == pytest.approx(1.02)
    same = ardupilot_params(cal, counts_per_unit={"mag": (1 / 0.15, "uT")})
    assert same == pytest.approx(p)
    # the user's scale wins over the model's
    other = ardupilot_params(cal, sensor_model="ICM-20948",
                                counts_per_unit={"mag": (1090, "gauss")})
    assert other["COMPASS_OFS_X"] == pytest.approx(-200.0 / 1090 * 1000)


def test_ardupilot_refusal_names_the_scale_it_used():
    """Before: an offset out of range blamed "the fit was not determined by the data"."""
    cal = _counts_mag()
    with pytest.raises(tc.CalibrationError) as exc:
        ardupilot_params(cal, counts_per_unit={"mag": (0.01, "uT")})  # a wrong scale
    msg = str(exc.value)
    assert "COMPASS_OFFS_MAX" in msg and "0.01:uT" in msg and "not determined" not in msg


def test_the_sensor_table():
    from triaxcal.conventions.sensors import SENSOR_MODELS, find_model, model_scale

    names = {m.name for m in SENSOR_MODELS} | {a for m in SENSOR_MODELS for a in m.aliases}
    for want in ("MPU-6050", "MPU-9250", "AK8963", "ICM-20948", "AK09916", "LSM9DS1", "LSM6DSO",
                 "BMI160", "BMI270", "BMM150", "HMC5883L", "QMC5883L", "LIS3MDL", "MMC5983MA",
                 "IST8310"):
        assert want in names
    from triaxcal.conventions.units import UNITS

    for m in SENSOR_MODELS:
        for sensor, settings in m.sensors.items():
            for s in settings:
                assert s.counts_per_unit > 0 and "table" in s.source.lower()
                assert UNITS[s.unit][0] == sensor
    cases = [("MPU-6050:2g", "accel", 16384, "g"), ("MPU-6050:250dps", "gyro", 131, "deg/s"),
             ("ICM-20948", "mag", 1 / 0.15, "uT"), ("MPU-9250:14bit", "mag", 1 / 0.6, "uT"),
             ("HMC5883L:1.3gauss", "mag", 1090, "gauss"), ("QMC5883L:8gauss", "mag", 3000,
                                                            "gauss"),
             ("LIS3MDL:4gauss", "mag", 6842, "gauss"), ("LSM9DS1:16g", "accel", 1 / 0.732, "mg"),
             ("LSM6DSOX:2000dps", "gyro", 1 / 0.07, "deg/s"), ("BMI270:125dps", "gyro", 262.4,
                                                                "deg/s"),
             ("MMC5983MA:18bit", "mag", 16384, "gauss"), ("IST8310", "mag", 1 / 0.3, "uT"),
             ("BMM150", "mag", 1 / 0.3, "uT"), ("mag=AK09916", "mag", 1 / 0.15, "uT")]
    for spec, sensor, cpu, unit in cases:
        s = model_scale(spec, sensor)
        assert (s.counts_per_unit, s.unit) == (pytest.approx(cpu), unit), spec
    with pytest.raises(tc.CalibrationError, match="known ones are .*ICM-20948"):
        find_model("ICM-99999")
    with pytest.raises(tc.CalibrationError, match="full-scale settings"):
        model_scale("MPU-6050", "accel")
    with pytest.raises(tc.CalibrationError, match="has no mag"):
        model_scale("MPU-6050:2g", "mag")
    with pytest.raises(tc.CalibrationError, match="unknown sensor model"):
        ardupilot_params(_counts_mag(), sensor_model="NOPE-1")


def test_no_silent_default_scale_is_left():
    import triaxcal.conventions.units as units
    import triaxcal.export as ex

    assert not hasattr(units, "DEVICE_COUNTS_PER_UNIT")
    assert not hasattr(ex, "DEVICE_COUNTS_PER_UNIT")
    counts_acc = tc.Calibration(accel=tc.SensorCalibration(
        offset=[10, -20, 30], matrix=np.eye(3) / 16384, unit="g"))
    for call in (lambda: tc.motioncal_packet(counts_acc, offsets_only=True),
                 lambda: tc.export.motioncal_losses(counts_acc),
                 lambda: kalibr_intrinsics(counts_acc.replace(gyro=tc.SensorCalibration(
                     offset=[1, 2, 3], matrix=np.eye(3) / 131, unit="deg/s")))):
        with pytest.raises(tc.CalibrationError, match="does not guess"):
            call()


# ------------------------------------------------------------------------ adafruit


def test_adafruit_needs_the_field_and_writes_only_the_chosen_parts(tmp_path, capsys):
    """Before: mag_field 348 for a fit without a radius; accel_zerog [0, 0, 0] with
    --sensors mag,gyro."""
    cal = _counts_mag().replace(gyro=tc.SensorCalibration(
        offset=[40, -12, 7], matrix=np.eye(3) / 131, unit="deg/s"),
        accel=tc.SensorCalibration(offset=[10, -20, 30], matrix=np.eye(3) / 16384, unit="g"))
    path = tmp_path / "c.json"
    cal.save(path)
    out = tmp_path / "sensor_calib.json"
    base = ["export", str(path), "--format", "adafruit", "--sensors", "mag,gyro", "-o", str(out),
            "--sensor-model", "ICM-20948:250dps"]
    assert main(base) == 1
    assert "--mag-field" in capsys.readouterr().err and not out.exists()
    assert main([*base, "--mag-field", "48uT"]) == 0
    printed = capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["mag_field"] == pytest.approx(48.0)
    assert set(d) == {"mag_hardiron", "mag_softiron", "mag_field", "gyro_zerorate"}
    assert "sensors: mag, gyro" in printed and "accel_zerog" in printed
    assert "missing key as 0" in printed
    # a part fitted to the field: mag_field is its radius in uT
    fitted = _counts_mag().mag.replace(unit="uT", matrix=np.eye(3) * 0.15, radius=48.0)
    d = adafruit_calib(tc.Calibration(mag=fitted), sensor_model="AK09916")
    assert d["mag_field"] == pytest.approx(48.0)


def test_summaries_list_exactly_what_was_written(tmp_path, capsys):
    """Before: `--sensors mag` printed "sensors: accel, mag"."""
    path = tmp_path / "c.json"
    tc.Calibration(accel=_acc(), mag=_mag()).save(path)
    for fmt in ("ardupilot", "px4"):
        assert main(["export", str(path), "--format", fmt, "--sensors", "mag", "-o",
                     str(tmp_path / f"x.{fmt}")]) == 0
        assert "sensors: mag)" in capsys.readouterr().out
        text = (tmp_path / f"x.{fmt}").read_text()
        assert "\nINS_ACC" not in text and "\tCAL_ACC" not in text
    assert main(["export", str(path), "--format", "kalibr", "--rate-hz", "200",
                 "--kalibr-model", "calibrated", "-o", str(tmp_path / "k.yaml")]) == 0
    assert "sensors: accel)" in capsys.readouterr().out


# ------------------------------------------------------------------------ autopilot corrections


def _ap_compass_params():
    return {"COMPASS_OFS_X": 35.0, "COMPASS_OFS_Y": -120.0, "COMPASS_OFS_Z": 60.0,
            "COMPASS_DIA_X": 1.03, "COMPASS_DIA_Y": 0.97, "COMPASS_DIA_Z": 1.01,
            "COMPASS_ODI_X": 0.01, "COMPASS_ODI_Y": -0.02, "COMPASS_ODI_Z": 0.015,
            "COMPASS_SCALE": 1.05}


def _correction_part(stored, params, autopilot, raw_unit, rng, *, matrix=None):
    """A part fitted on what the autopilot logged (stored applied), as `fit` records it."""
    m = np.eye(3) + rng.normal(scale=0.01, size=(3, 3)) if matrix is None else matrix
    m = (m + m.T) / 2
    stats = {"log": {"format": f"{autopilot}-log", "calibrated_by_autopilot": True},
             "autopilot": {"autopilot": autopilot, "slot": 0, "unit": stored.unit,
                           "equation": stored.equation, "source": stored.citation,
                           "params": params, "offset": stored.triaxcal_offset.tolist(),
                           "matrix": stored.triaxcal_matrix.tolist()}}
    o_fit = rng.normal(size=3) * (20.0 if raw_unit == "mG" else 0.05)
    return tc.SensorCalibration(offset=o_fit, matrix=m, raw_unit=raw_unit, unit=raw_unit,
                                stats=stats, model="full")


def test_ardupilot_compass_correction_is_exported_composed():
    """Before: the correction was written as COMPASS_OFS, replacing the stored calibration."""
    rng = np.random.default_rng(3)
    params = _ap_compass_params()
    stored = ardupilot_part(params, "mag", 0)
    # a correction that keeps the composed soft iron symmetric (a gain and a hard iron)
    part = _correction_part(stored, params, "ardupilot", "mG", rng, matrix=np.eye(3) * 1.03)
    p = ardupilot_params(tc.Calibration(mag=part), compass_scale=None)
    raw = rng.normal(size=(200, 3)) * 400
    logged = stored.apply(raw)  # what ArduPilot logged
    want = part.apply(logged)  # what the fit makes of it
    # ArduPilot's own correct_field with the exported parameters (COMPASS_SCALE off)
    m = np.array([[p["COMPASS_DIA_X"], p["COMPASS_ODI_X"], p["COMPASS_ODI_Y"]],
                  [p["COMPASS_ODI_X"], p["COMPASS_DIA_Y"], p["COMPASS_ODI_Z"]],
                  [p["COMPASS_ODI_Y"], p["COMPASS_ODI_Z"], p["COMPASS_DIA_Z"]]])
    ofs = np.array([p[f"COMPASS_OFS_{a}"] for a in "XYZ"])
    got = (raw + ofs) @ m.T
    assert np.max(np.abs(got - want)) < 1e-6 * np.abs(want).max()
    text = tc.ardupilot_parm(tc.Calibration(mag=part))
    assert "composed absolute calibration" in text and "correct_field" in text


def test_px4_accel_correction_with_a_board_rotation_is_exported_composed():
    rng = np.random.default_rng(4)
    params = {"CAL_ACC0_XOFF": 0.12, "CAL_ACC0_YOFF": -0.3, "CAL_ACC0_ZOFF": 0.05,
              "CAL_ACC0_XSCALE": 1.01, "CAL_ACC0_YSCALE": 0.99, "CAL_ACC0_ZSCALE": 1.02,
              "SENS_BOARD_ROT": 2.0}  # yaw 90: the correction happens before the rotation
    stored = px4_part(params, "accel", 0)
    part = _correction_part(stored, params, "px4", "m/s^2", rng,
                            matrix=np.diag([1.004, 0.997, 1.001]))
    got = dict((n, v) for n, v, _ in px4_params(tc.Calibration(accel=part)))
    raw = rng.normal(size=(100, 3)) * 9.8
    off = np.array([got[f"CAL_ACC0_{a}OFF"] for a in "XYZ"])
    sc = np.array([got[f"CAL_ACC0_{a}SCALE"] for a in "XYZ"])
    body = ((raw - off) * sc) @ stored.rotation.T  # PX4: rotate after the correction
    want = part.apply(stored.apply(raw))
    assert np.max(np.abs(body - want)) < 1e-9 * np.abs(want).max()


def test_a_correction_without_its_stored_calibration_is_refused():
    part = _mag(stats={"log": {"format": "px4-ulog", "calibrated_by_autopilot": True}})
    with pytest.raises(tc.CalibrationError, match="correction, not the sensor's calibration"):
        tc.c_header(tc.Calibration(mag=part))
    rng = np.random.default_rng(0)
    params = {**_ap_compass_params()}
    stored = ardupilot_part(params, "mag", 0)
    edited = _correction_part(stored, params, "ardupilot", "mG", rng)
    edited.stats["autopilot"]["offset"] = [0.0, 0.0, 0.0]
    with pytest.raises(tc.CalibrationError, match="does not match"):
        ardupilot_params(tc.Calibration(mag=edited))


@pytest.mark.slow
def test_px4_log_correction_exports_composed(realdata, tmp_path, capsys):
    """The issue's: sample.ulg's magnetometer fitted on sensor_combined (already corrected by
    PX4's stored offsets 0.028 / -0.200 / -0.137 gauss) gave CAL_MAG0_XOFF -0.079."""
    log = realdata / "px4-pyulog-samples" / "sample.ulg"
    cal_path = tmp_path / "u.json"
    assert main(["fit", str(log), "--sensor", "mag", "--force", "-o", str(cal_path)]) == 0
    part = tc.Calibration.load(cal_path).mag
    assert "device_id" in part.stats["log"]  # recorded (None: this log does not carry it)
    capsys.readouterr()
    out = tmp_path / "u.params"
    assert main(["export", str(cal_path), "--format", "px4", "--force", "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    p = {ln.split("\t")[2]: float(ln.split("\t")[3]) for ln in out.read_text().splitlines()
         if not ln.startswith("#")}
    stored = np.array(part.stats["autopilot"]["offset"])
    assert p["CAL_MAG0_XOFF"] != pytest.approx(part.offset[0], abs=1e-6)
    # the composed offset is the stored one plus the correction (the rotation is ~1.5 deg)
    np.testing.assert_allclose([p[f"CAL_MAG0_{a}OFF"] for a in "XYZ"], stored + part.offset,
                               atol=0.01)
    assert "composed absolute calibration" in printed
    assert "CAL_MAG0_ID not written" in printed and "CAL_MAG0_ID not written" in out.read_text()


def test_px4_device_id_from_the_log():
    stats = {"log": {"format": "px4-ulog", "calibrated_by_autopilot": False,
                     "device_id": 2424842}}
    cal = tc.Calibration(accel=_acc(stats=stats))
    got = {n: v for n, v, _ in px4_params(cal)}
    assert got["CAL_ACC0_ID"] == 2424842
    assert "not written" not in tc.px4_params_file(cal)
    given = {n: v for n, v, _ in px4_params(cal, device_ids={"accel": 77})}
    assert given["CAL_ACC0_ID"] == 77
    text = tc.px4_params_file(tc.Calibration(accel=_acc()))
    comments = " ".join(ln[2:] for ln in text.splitlines() if ln.startswith("# "))
    assert "CAL_ACC0_ID not written" in comments and "device_ids={'accel': ID}" in comments


# ------------------------------------------------------------------------ Kalibr YAML


def _numbers(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _numbers(v)
    else:
        yield obj


def test_kalibr_yaml_numbers_are_floats_for_safe_load(tmp_path, capsys):
    """Before: `2e-05` (repr) came back from yaml.safe_load as the string '2e-05'."""
    noise = {"accelerometer_noise_density": 2e-05, "accelerometer_random_walk": 3e-05,
             "gyroscope_noise_density": 4e-06, "gyroscope_random_walk": 1e-07}
    npath = tmp_path / "noise.json"
    npath.write_text(json.dumps(noise))
    # small terms whose repr has no decimal point (1e-05) must come back as floats too
    cal = tc.Calibration(accel=_acc(matrix=np.array([[1.01, 0, 0], [1e-5, 0.99, 0],
                                                     [0, 2e-5, 1.0]])),
                         gyro=_gyr(matrix=np.diag([1.0, 1.0 + 1e-7, 1.0])))
    cpath = tmp_path / "c.json"
    cal.save(cpath)
    out = tmp_path / "imu.yaml"
    assert main(["export", str(cpath), "--format", "kalibr", "--rate-hz", "200",
                 "--noise", str(npath), "-o", str(out)]) == 0
    d = yaml.safe_load(out.read_text())
    for key, v in noise.items():
        assert d[key] == v and isinstance(d[key], float)
    assert isinstance(d["update_rate"], float)
    nums = [x for x in _numbers({k: v for k, v in d.items() if k != "invalid_reasons"})
            if not isinstance(x, (str, bool))]
    assert len(nums) >= 4 + 1 + 27
    assert all(isinstance(x, float) for x in nums), [x for x in nums if not isinstance(x, float)]
    strings = [x for x in _numbers(d) if isinstance(x, str)]
    assert all(not _looks_numeric(s) for s in strings), strings
    k = kalibr_intrinsics(cal)  # the values read back are the ones computed, exactly
    assert np.array_equal(np.array(d["accelerometers"]["M"]), k["M_accel"])
    assert np.array_equal(np.array(d["gyroscopes"]["C_gyro_i"]), k["C_gyro_i"])


def _looks_numeric(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def test_yaml_float_round_trips():
    from triaxcal.export.kalibr import yaml_float

    for v in (2e-05, 3e-05, 4e-06, 1e-300, 5e-324, 1.7976931348623157e308, -0.0, 200.0,
              0.1, 123456789.0, 1e16, -2.5e-10):
        t = yaml_float(v)
        back = yaml.safe_load(f"x: {t}")["x"]
        assert isinstance(back, float) and back == v, (v, t)
    with pytest.raises(tc.CalibrationError):
        yaml_float(float("inf"))
    text = kalibr_imu_yaml(None, rate_hz=0.001, model="calibrated")
    assert isinstance(yaml.safe_load(text)["update_rate"], float)
    with pytest.raises(tc.CalibrationError, match="rate_hz must be a finite number in"):
        kalibr_imu_yaml(None, rate_hz=1e-05, model="calibrated")  # one sample in 28 hours


# ------------------------------------------------------------------------ C headers


def _compile(header, tmp_path, fixed=False):
    src = tmp_path / "main.c"
    src.write_text(f'#include "{header.name}"\nint main(void) {{ return 0; }}\n')
    subprocess.run([GCC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c",
                    str(src), "-I", str(header.parent), "-o", str(tmp_path / "main.o")],
                   check=True, capture_output=True)


def test_float_header_refuses_coefficients_beyond_float(tmp_path):
    """Before: `inff` in the header, which does not compile. Such coefficients (past 1e15 in
    any unit) are now refused when the part is made, before any header."""
    for kw in ({"matrix": np.eye(3) * 1e39}, {"offset": [1e40, 0, 0]}, {"radius": 5e38}):
        with pytest.raises(tc.CalibrationError, match=r"larger than 1e\+15|must lie in"):
            part = tc.SensorCalibration(**{"offset": [1, 2, 3], "matrix": np.eye(3),
                                           "raw_unit": "counts", "unit": "counts", **kw})
            tc.c_header(tc.Calibration(accel=part), force=True)


@pytest.mark.skipif(GCC is None, reason="gcc not installed")
def test_headers_compile_including_forced_and_composed(tmp_path):
    rng = np.random.default_rng(5)
    params = _ap_compass_params()
    composed = _correction_part(ardupilot_part(params, "mag", 0), params, "ardupilot", "mG",
                                rng)
    cases = {"valid": tc.Calibration(accel=_acc(), mag=_mag()), "forced": _invalid_cal(),
             "composed": tc.Calibration(mag=composed)}
    for name, cal in cases.items():
        h = tmp_path / f"{name}.h"
        h.write_text(tc.c_header(cal, force=True))
        _compile(h, tmp_path)
    fixed = tc.Calibration(accel=tc.SensorCalibration(offset=[10, -20, 30],
                                                      matrix=np.eye(3) / 16384, unit="g",
                                                      valid=False, invalid_reasons=(REASON,)))
    h = tmp_path / "fixed.h"
    h.write_text(tc.c_fixed_header(fixed, force=True))
    _compile(h, tmp_path)


def test_fixed_point_header_refuses_what_q24_cannot_carry():
    """Before: OUT_SCALE_NUM 0 for a huge matrix, and rows that round to 0."""
    from triaxcal.export.c_fixed import apply_fixed, fixed_point

    huge = tc.SensorCalibration(offset=[1, 2, 3], matrix=np.eye(3) * 1e8, raw_unit="counts",
                                unit="counts")
    with pytest.raises(tc.CalibrationError, match="OUT_SCALE"):
        tc.c_fixed_header(tc.Calibration(accel=huge), force=True)
    lopsided = huge.replace(matrix=np.diag([1e5, 1.0, 1.0]))
    with pytest.raises(tc.CalibrationError, match="row 1"):
        fixed_point(lopsided)
    with pytest.raises(tc.CalibrationError, match="beyond int32"):
        fixed_point(huge.replace(offset=[2e9, 0, 0], matrix=np.eye(3) * 1.5))
    ok = fixed_point(huge.replace(matrix=np.eye(3) / 16384))
    out = apply_fixed(ok, [[16384, -16384, 1000]])
    assert out.tolist() != [[0, 0, 0]]


# ------------------------------------------------------------------------ the command's grammar


def test_export_grammar(tmp_path, capsys):
    from triaxcal.cli import build_parser

    sub = next(a for a in build_parser()._actions if hasattr(a, "choices") and a.choices and
               "export" in a.choices)
    helptext = " ".join(sub.choices["export"].format_help().split())
    for fmt in EXPORT_FORMATS:
        assert f"{fmt}:" in helptext, fmt
    for flag in ("--ros-topic", "--rate-hz", "--counts-per-unit", "--sensor-model", "--force",
                 "-o FILE, --output FILE"):
        assert flag in helptext, flag
    path = tmp_path / "c.json"
    tc.Calibration(accel=_acc(), gyro=_gyr()).save(path)
    out = tmp_path / "imu.yaml"
    assert main(["export", str(path), "--format", "kalibr", "--rate", "100", "--topic",
                 "/imu/data", "--output", str(out)]) == 0
    err = capsys.readouterr().err
    assert "--topic is now --ros-topic" in err and "--rate is now --rate-hz" in err
    d = yaml.safe_load(out.read_text())
    assert d["rostopic"] == "/imu/data" and d["update_rate"] == 100.0
    assert main(["export", str(path), "--format", "c", "--counts-per-unit", "accel=16384",
                 "-o", str(tmp_path / "x.h")]) == 1
    assert "apply to the formats in physical units" in capsys.readouterr().err
    for cmd in (["export", str(path), "--format", "px4", "-o", str(tmp_path / "y")],
                ["send", str(path), "--port", "loop://"]):
        with pytest.raises(SystemExit):
            main([*cmd, "--counts-per-unit", "accel16384"])
        assert "SENSOR=COUNTS[:UNIT]" in capsys.readouterr().err
