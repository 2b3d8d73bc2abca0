"""`triaxcal fit` with --radius wmm / --location / --date, --align and --yaw-only, and the
report's lines for them."""

from __future__ import annotations

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.cli import main
from triaxcal.conventions.rotations import mounting
from triaxcal.io.protocol import CHANNELS_10

pytest.importorskip("wmm", reason="the geo extra (wmm-calculator)")

LOC, DATE = "47.37,8.54,408", "2026-05-17"


@pytest.fixture(scope="module")
def wmm():
    return tc.expected_field(47.37, 8.54, 408.0, date=DATE)


def _session(path, wmm, *, field_scale=1.0, mount=None, mag_unit_per_count=None, seed=5):
    """A simulated capture session; the magnetometer optionally turned by ``mount`` and/or
    written in uT instead of counts."""
    imu = tc.sim.SimIMU(seed=seed, field_ut=wmm.total_ut * field_scale,
                        inclination_deg=wmm.inclination_deg)
    rec = imu.record(tc.sim.globe_script(hold_s=1.0, seed=seed), rate_hz=100)
    fr = rec.frames(10).astype(float)
    if mount is not None:  # the magnetometer chip mounted turned: v_accel = mount @ v_mag
        tr = imu.truth.mag
        f_mag = rec.mag_ut @ mount
        fr[:, 6:9] = np.rint(f_mag @ np.linalg.inv(tr.matrix).T + tr.offset)
    if mag_unit_per_count is not None:
        fr[:, 6:9] *= mag_unit_per_count
    np.savetxt(path, fr, delimiter=",", header=",".join(CHANNELS_10), comments="", fmt="%.6g")
    return imu


def test_radius_wmm_is_the_total_field(tmp_path, wmm, capsys):
    s = tmp_path / "s.csv"
    _session(s, wmm, mag_unit_per_count=0.1)  # 10 counts per uT: the readings in uT
    cal = tmp_path / "cal.json"
    assert main(["fit", str(s), "--sensor", "mag", "--raw-unit", "uT", "--radius", "wmm",
                 "--location", LOC, "--date", DATE, "-o", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "expected field: WMM2025 at 47.3700, 8.5400, 408 m on 2026-05-17" in out
    part = tc.Calibration.load(cal).mag
    assert part.radius == pytest.approx(wmm.total_ut)
    assert part.expected_field == wmm
    # the simulator's soft iron scales by up to +-8 %: the strength shown is within 10 %
    assert part.stats["field_strength_ut"] == pytest.approx(wmm.total_ut, rel=0.1)
    assert not any("World Magnetic Model" in w for w in part.stats["warnings"])
    assert main(["report", str(cal)]) == 0
    rep = capsys.readouterr().out
    assert "expected field  WMM2025" in rep and "inclination 63.50 deg" in rep
    assert "the readings show" in rep


def test_magnetised_environment_is_warned(tmp_path, wmm, capsys):
    s = tmp_path / "s.csv"
    _session(s, wmm, field_scale=1.3, mag_unit_per_count=0.1)
    cal = tmp_path / "cal.json"
    assert main(["fit", str(s), "--sensor", "mag", "--raw-unit", "uT", "--radius", "wmm",
                 "--location", LOC, "--date", DATE, "-o", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "warning: the field strength the readings show" in out
    assert "magnetised environment" in out
    part = tc.Calibration.load(cal).mag
    assert part.stats["field_strength_ut"] / wmm.total_ut == pytest.approx(1.3, abs=0.1)


@pytest.mark.parametrize("extra, match", [
    (["--radius", "wmm"], "needs --location"),
    (["--date", DATE], "--date needs --location"),
    (["--location", "91,0"], "latitude"),
    (["--location", "47,8", "--date", "2012-01-01"], "2024-11-13 to 2029-12-31"),
    (["--location", "47,8", "--sensor", "accel"], "applies to --sensor mag"),
    (["--yaw-only", "--sensor", "accel"], "applies to --sensor mag"),
])
def test_bad_field_options(tmp_path, wmm, capsys, extra, match):
    s = tmp_path / "s.csv"
    s.write_text("mx,my,mz\n1,2,3\n4,5,6\n")
    args = ["fit", str(s), "-o", str(tmp_path / "c.json")] + extra
    if "--sensor" not in extra:
        args += ["--sensor", "mag"]
    assert main(args) != 0
    assert match in capsys.readouterr().err


def test_align_finds_the_mounting_and_is_stored(tmp_path, wmm, capsys):
    s = tmp_path / "s.csv"
    mount = mounting("ROTATION_YAW_270").matrix
    _session(s, wmm, mount=mount, seed=8)
    cal = tmp_path / "cal.json"
    # without the accelerometer's calibration first: refused
    assert main(["fit", str(s), "--sensor", "mag", "--align", "-o", str(cal)]) != 0
    assert "fit it first" in capsys.readouterr().err
    assert main(["fit", str(s), "--sensor", "accel", "--poses", "-o", str(cal)]) == 0
    assert main(["fit", str(s), "--sensor", "mag", "--radius", "wmm", "--location", LOC,
                 "--date", DATE, "--align", "-o", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "mounting ROTATION_YAW_270 (6)" in out
    part = tc.Calibration.load(cal).mag
    assert part.alignment.mounting == "ROTATION_YAW_270"
    assert tc.rotations.rotation_angle_deg(part.alignment.rotation, mount) < 0.2
    assert part.alignment.stats["dip_deg"] == pytest.approx(wmm.inclination_deg, abs=0.3)
    assert main(["report", str(cal), "--sensor", "mag"]) == 0
    rep = capsys.readouterr().out
    assert "alignment       into the accel frame" in rep and "heading check" in rep
    # the parameter files carry it
    parm = tmp_path / "cal.parm"
    assert main(["export", str(cal), "--format", "px4", "--sensors", "mag",
                 "--counts-per-unit", "mag=10:uT",  # the simulator's scale
                 "-o", str(tmp_path / "p.params")]) == 0
    assert "CAL_MAG0_ROT\t6\t6" in (tmp_path / "p.params").read_text()
    del parm


def test_yaw_only_on_the_nliaudat_recording(realdata, tmp_path, capsys):
    src = realdata / "hmc5883l-yaw-nliaudat" / "mag_out_sample.txt"
    cal = tmp_path / "yaw.json"
    assert main(["fit", str(src), "--sensor", "mag", "--raw-unit", "uT", "--yaw-only",
                 "-o", str(cal)]) == 0
    out = capsys.readouterr().out
    assert "model yaw" in out and "NOT determined" in out
    part = tc.Calibration.load(cal).mag
    assert part.model == "yaw" and part.offset[:2] == pytest.approx([40.6, -89.1], abs=1.0)
    assert main(["report", str(cal)]) == 0
    rep = capsys.readouterr().out
    assert "yaw-only calibration" in rep and "limit:" in rep
    assert "sphere is empty" not in rep  # a band of the sphere is what turns give
    # with any location on Earth, 187 "uT" of horizontal field is far too much: readings that
    # claim to be uT but need gains of 0.11 are refused by the validity gate ...
    args = ["fit", str(src), "--sensor", "mag", "--raw-unit", "uT", "--yaw-only",
            "--location", LOC, "--date", DATE, "-o", str(tmp_path / "y2.json")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "not written" in err and "gains should lie near 1" in err
    assert not (tmp_path / "y2.json").exists()
    # ... and written with --force, marked not valid, the strength warning kept
    assert main([*args, "--force"]) == 0
    assert "horizontal field strength the readings show" in capsys.readouterr().out
    forced = tc.Calibration.load(tmp_path / "y2.json").mag
    assert forced.valid is False and any("gains" in r for r in forced.invalid_reasons)
