"""C headers compiled with gcc (run) and avr-gcc (compile + link), fixed point, MotionCal packet."""

from __future__ import annotations

import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from hypothesis import given, settings
from hypothesis import strategies as st
from triaxcal.export import (
    apply_fixed,
    c_fixed_header,
    c_header,
    crc16_modbus,
    decode_motioncal,
    encode_motioncal,
    fixed_point,
    motioncal_packet,
    parse_motioncal_echo,
    write_outputs,
)

GCC = shutil.which("gcc")
AVR_GCC = shutil.which("avr-gcc")
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]


def _part(rng, offset_scale, diag, unit, radius, temperature=None, symmetric=True):
    m = np.diag(diag) * rng.uniform(0.95, 1.05, 3)
    off = rng.normal(scale=0.02, size=(3, 3)) * np.mean(diag)
    m = m + (off + off.T if symmetric else off)
    return tc.SensorCalibration(
        offset=rng.normal(scale=offset_scale, size=3),
        matrix=m,
        raw_unit="counts",
        unit=unit,
        radius=radius,
        model="full",
        temperature=temperature,
        stats={"rms": 0.01 * (radius or 1.0), "n": 100, "rms_pct_of_radius": 1.0},
    )


@pytest.fixture
def cal() -> tc.Calibration:
    rng = np.random.default_rng(5)
    temp = tc.TemperatureTerms(
        temp_ref_c=25.0,
        temp_range_c=(5.0, 45.0),
        offset_poly=[[0.0, 0.0, 0.0], [3.1, -2.2, 1.7], [0.05, 0.02, -0.03]],
        gain_poly=[[0.0, 0.0, 0.0], [2e-4, -1e-4, 3e-4]],
    )
    return tc.Calibration(
        accel=_part(rng, 300, [1 / 16384] * 3, "g", 1.0),
        gyro=_part(rng, 50, [1 / 131] * 3, "deg/s", None, temperature=temp),
        mag=_part(rng, 200, [0.15] * 3, "uT", 48.0, symmetric=False),
        sensor_id="test-board",
    )


def _raw_vectors(cal, sensor, n=200, seed=1):
    rng = np.random.default_rng(seed)
    part = cal.part(sensor)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = part.radius or 200.0
    raw = part.offset + (u * r * rng.uniform(0.5, 1.5, (n, 1))) @ np.linalg.inv(part.matrix).T
    raw = np.clip(np.round(raw), -32768, 32767)
    extremes = np.array([[32767, 32767, 32767], [-32768, -32768, -32768], [32767, -32768, 0]])
    return np.vstack([raw, extremes]).astype(np.int64)


MAIN_FLOAT = r"""
#include <stdio.h>
#include "cal.h"
int main(void) {
    char s[16]; float raw[3], out[3], t;
    while (scanf("%15s %f %f %f %f", s, &raw[0], &raw[1], &raw[2], &t) == 5) {
        switch (s[0]) {
        case 'a': imu_accel_apply(raw, out); break;
        case 'g': imu_gyro_apply(raw, out); break;
        case 'G': imu_gyro_apply_t(raw, t, out); break;
        default: imu_mag_apply(raw, out); break;
        }
        printf("%.9g %.9g %.9g\n", out[0], out[1], out[2]);
    }
    return 0;
}
"""

MAIN_FIXED = r"""
#include <stdio.h>
#include "cal.h"
int main(void) {
    char s[16]; long r0, r1, r2, t; int16_t raw[3]; int32_t out[3];
    while (scanf("%15s %ld %ld %ld %ld", s, &r0, &r1, &r2, &t) == 5) {
        raw[0] = (int16_t)r0; raw[1] = (int16_t)r1; raw[2] = (int16_t)r2;
        switch (s[0]) {
        case 'a': imu_accel_apply_q(raw, out); break;
        case 'g': imu_gyro_apply_q(raw, out); break;
        case 'G': imu_gyro_apply_qt(raw, (int32_t)t, out); break;
        default: imu_mag_apply_q(raw, out); break;
        }
        printf("%ld %ld %ld\n", (long)out[0], (long)out[1], (long)out[2]);
    }
    return 0;
}
"""


def _build_and_run(tmp_path: Path, header: str, main: str, lines: list[str]) -> list[list[str]]:
    (tmp_path / "cal.h").write_text(header)
    (tmp_path / "main.c").write_text(main)
    exe = tmp_path / "main"
    subprocess.run([GCC, *CFLAGS, "-O2", "-o", str(exe), str(tmp_path / "main.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    res = subprocess.run([str(exe)], input="\n".join(lines) + "\n", check=True,
                         capture_output=True, text=True)
    return [ln.split() for ln in res.stdout.splitlines()]


@pytest.mark.skipif(GCC is None, reason="gcc not installed")
def test_float_header_matches_apply(cal, tmp_path):
    header = c_header(cal, prefix="imu")
    jobs, expect = [], []
    temps = np.random.default_rng(2).uniform(0, 50, 205)
    for key, sensor in (("a", "accel"), ("g", "gyro"), ("G", "gyro"), ("m", "mag")):
        raw = _raw_vectors(cal, sensor)
        t = temps[: len(raw)]
        if key == "G":
            want = cal.apply(raw, sensor=sensor, temperature=t)
        elif sensor == "gyro":
            want = cal.apply(raw, sensor=sensor, temperature=25.0)
        else:
            want = cal.apply(raw, sensor=sensor)
        # float32 temperatures, as the C program reads them
        t32 = t.astype(np.float32)
        if key == "G":
            want = cal.apply(raw, sensor=sensor, temperature=t32.astype(float))
        jobs += [f"{key} {r[0]} {r[1]} {r[2]} {float(tt)!r}" for r, tt in zip(raw, t32)]
        expect.append(want)
    got = np.array(_build_and_run(tmp_path, header, MAIN_FLOAT, jobs), dtype=float)
    want = np.vstack(expect)
    err = np.linalg.norm(got - want, axis=1) / np.linalg.norm(want, axis=1)
    assert err.max() < 1e-6, err.max()
    # the header's own test vector is what cal.apply gives
    assert "test vector: imu_accel_apply(" in header


@pytest.mark.skipif(GCC is None, reason="gcc not installed")
def test_fixed_header_within_one_count(cal, tmp_path):
    header = c_fixed_header(cal, prefix="imu")
    assert "float" not in header.split("#ifndef IMU_CALIBRATION_FIXED_H", 1)[1]
    assert "double" not in header
    jobs, model, exact = [], [], []
    temps = np.random.default_rng(3).uniform(0, 50, 205)
    for key, sensor in (("a", "accel"), ("g", "gyro"), ("G", "gyro"), ("m", "mag")):
        part = cal.part(sensor)
        fp = fixed_point(part)
        raw = _raw_vectors(cal, sensor, seed=4)
        tq8 = np.round(temps[: len(raw)] * 256).astype(np.int64)
        if key == "G":
            model.append(apply_fixed(fp, raw, tq8))
            exact.append(part.apply(raw, temperature=tq8 / 256.0) * fp.out_scale)
        else:
            model.append(apply_fixed(fp, raw))
            t = part.temperature.temp_ref_c if part.temperature else None
            exact.append(part.apply(raw, temperature=t) * fp.out_scale)
        jobs += [f"{key} {r[0]} {r[1]} {r[2]} {tt}" for r, tt in zip(raw, tq8)]
    got = np.array(_build_and_run(tmp_path, header, MAIN_FIXED, jobs), dtype=np.int64)
    assert np.array_equal(got, np.vstack(model))  # the Python model is bit-exact
    diff = np.abs(got - np.vstack(exact))
    assert diff.max() <= 1.0, diff.max()
    assert np.abs(np.vstack(exact)).max() > 1000  # not a trivially small output range


def test_fixed_point_default_scale_keeps_resolution(cal):
    fp = fixed_point(cal.accel)
    ms = np.max(np.abs(cal.accel.matrix)) * fp.out_scale
    assert 1.0 <= ms < 2.0
    assert fp.offset == tuple(int(np.sign(v) * np.floor(abs(v) + 0.5)) for v in cal.accel.offset)
    fp1000 = fixed_point(cal.accel, out_scale=1000)  # milli-g
    raw = [[16384, 0, 0]]
    assert abs(apply_fixed(fp1000, raw)[0, 0] - cal.accel.apply(raw)[0, 0] * 1000) <= 1


def test_fixed_header_rejects_float_raw():
    part = tc.SensorCalibration(offset=[0, 0, 0], matrix=np.eye(3), raw_unit="g", unit="g")
    with pytest.raises(tc.CalibrationError, match="integer raw readings"):
        c_fixed_header(tc.Calibration(accel=part))


HARNESS_AVR = r"""
#include <stdint.h>
#include "cal.h"
#include "calq.h"
volatile float sink_f[3];
volatile int32_t sink_q[3];
int main(void) {
    float raw[3] = {1.0f, 2.0f, 3.0f}, out[3];
    int16_t rq[3] = {100, -200, 300};
    int32_t oq[3];
    int i;
    imu_accel_apply(raw, out); imu_gyro_apply_t(raw, 30.0f, out); imu_mag_apply(raw, out);
    for (i = 0; i < 3; i++) sink_f[i] = out[i];
    imu_accel_apply_q(rq, oq); imu_gyro_apply_qt(rq, 7680, oq); imu_mag_apply_q(rq, oq);
    for (i = 0; i < 3; i++) sink_q[i] = oq[i];
    return 0;
}
"""


@pytest.mark.skipif(AVR_GCC is None, reason="avr-gcc missing: run `make deps` (gcc-avr avr-libc)")
def test_headers_compile_and_link_for_avr(cal, tmp_path):
    (tmp_path / "cal.h").write_text(c_header(cal, prefix="imu"))
    (tmp_path / "calq.h").write_text(c_fixed_header(cal, prefix="imu"))
    (tmp_path / "main.c").write_text(HARNESS_AVR)
    elf = tmp_path / "main.elf"
    res = subprocess.run(
        [AVR_GCC, "-mmcu=atmega328p", "-Os", *CFLAGS, "-o", str(elf), str(tmp_path / "main.c")],
        check=False, capture_output=True, text=True,
    )
    assert res.returncode == 0, res.stderr
    assert elf.stat().st_size > 0


def test_header_macros_and_guard(cal):
    h = c_header(cal, prefix="imu")
    assert h.count("#ifndef IMU_CALIBRATION_H") == 1 and "#endif /* IMU_CALIBRATION_H */" in h
    for name in ("IMU_ACCEL_OFFSET_X", "IMU_ACCEL_DIAG_Z", "IMU_ACCEL_OFFDIAG_XY",
                 "IMU_MAG_OFFDIAG_ZY", "IMU_ACCEL_RADIUS", "IMU_GYRO_TEMP_REF_C"):
        assert f"#define {name} " in h
    assert "static const float imu_accel_matrix[3][3]" in h
    assert "static inline void imu_accel_apply(const float raw[3], float out[3])" in h
    # macros hold the float32 value of the coefficient
    line = next(ln for ln in h.splitlines() if ln.startswith("#define IMU_ACCEL_OFFSET_X "))
    assert np.float32(float(line.split()[-1].rstrip("f"))) == np.float32(cal.accel.offset[0])
    with pytest.raises(tc.CalibrationError, match="C identifier"):
        c_header(cal, prefix="9lives")


# ---- MotionCal packet ---------------------------------------------------------------------


def test_crc16_modbus_check_value():
    assert crc16_modbus(b"123456789") == 0x4B37
    assert crc16_modbus(b"") == 0xFFFF


def test_packet_hand_checked_bytes():
    pkt = encode_motioncal(
        accel_offset=(0, 0, 0), gyro_offset=(0, 0, 0), mag_offset=(1.0, -2.0, 0.5), field=50.0,
        soft_iron=np.eye(3),
    )
    assert len(pkt) == 68
    assert pkt[:2] == bytes([117, 84])
    # 1.0f = 00 00 80 3F, -2.0f = 00 00 00 C0, 0.5f = 00 00 00 3F, 50.0f = 00 00 48 42
    assert pkt[2:26] == bytes(24)
    assert pkt[26:42] == bytes.fromhex("0000803f000000c00000003f00004842")
    assert pkt[42:54] == bytes.fromhex("0000803f" * 3)
    assert pkt[54:66] == bytes(12)
    crc = crc16_modbus(pkt[:66])
    assert pkt[66:] == bytes([crc & 0xFF, crc >> 8])
    dec = decode_motioncal(pkt)
    assert dec.mag_offset == (1.0, -2.0, 0.5) and dec.field == 50.0
    assert dec.soft_iron == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def test_packet_decoder_checks_crc_and_header():
    pkt = bytearray(encode_motioncal(field=48.0))
    pkt[10] ^= 0x01
    with pytest.raises(tc.CalibrationError, match="CRC"):
        decode_motioncal(bytes(pkt))
    with pytest.raises(tc.CalibrationError, match="68 bytes"):
        decode_motioncal(bytes(pkt[:60]))
    bad = b"\x00\x00" + bytes(pkt[2:66])
    with pytest.raises(tc.CalibrationError, match="not a MotionCal packet"):
        decode_motioncal(bad + struct.pack("<H", crc16_modbus(bad)))


#: The board driver's scale of these tests' parts in counts (given: no export assumes one).
DRIVER = {"accel": (16384, "g"), "gyro": (131, "deg/s"), "mag": (10, "uT")}


def test_packet_from_calibration_units(cal):
    sym_mag = tc.SensorCalibration(
        offset=[100.0, -50.0, 20.0], matrix=np.array([[0.11, 0.002, 0], [0.002, 0.1, 0],
                                                      [0, 0, 0.09]]),
        unit="uT", radius=48.0,
    )
    c = cal.replace(mag=sym_mag)
    lost = tc.export.motioncal_losses(c, counts_per_unit=DRIVER)
    assert any(m.startswith("accelerometer: gains") for m in lost)
    assert any(m.startswith("gyro: temperature terms") for m in lost) == (
        c.gyro.temperature is not None)
    with pytest.raises(tc.CalibrationError, match="cannot carry all"):
        # the accelerometer's gains would be lost unnoticed
        motioncal_packet(c, counts_per_unit=DRIVER)
    p = decode_motioncal(motioncal_packet(c, offsets_only=True, counts_per_unit=DRIVER))
    # accel: counts / 16384 * 9.80665 m/s^2; gyro: counts / 131 deg/s in rad/s; mag: counts / 10
    np.testing.assert_allclose(p.accel_offset, c.accel.offset / 16384 * 9.80665, rtol=1e-6)
    np.testing.assert_allclose(p.gyro_offset, np.radians(c.gyro.offset / 131), rtol=1e-6)
    np.testing.assert_allclose(p.mag_offset, [10.0, -5.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(np.array(p.soft_iron), sym_mag.matrix * 10, rtol=1e-6)
    assert p.field == pytest.approx(48.0)
    # the packet reproduces the calibration: S (k raw - V) == M (raw - offset)
    raw = np.array([300.0, -20.0, 55.0])
    mine = sym_mag.apply(raw)
    theirs = np.array(p.soft_iron) @ (raw / 10 - np.array(p.mag_offset))
    np.testing.assert_allclose(theirs, mine, rtol=1e-5)
    with pytest.raises(tc.CalibrationError, match="symmetric"):
        # the fixture's mag matrix is not symmetric
        motioncal_packet(cal, offsets_only=True, counts_per_unit=DRIVER)


def test_packet_of_offsets_only_loses_nothing():
    """A calibration the packet holds whole (nominal-scale accelerometer, symmetric soft iron,
    no temperature terms) needs no opt-in."""
    c = tc.Calibration(
        accel=tc.SensorCalibration(offset=[12, -3, 40], matrix=np.eye(3) / 16384, unit="g"),
        mag=tc.SensorCalibration(offset=[100, -50, 20], matrix=np.eye(3) * 0.1, unit="uT",
                                 radius=48.0))
    assert tc.export.motioncal_losses(c, counts_per_unit=DRIVER) == []
    pkt = decode_motioncal(motioncal_packet(c, counts_per_unit=DRIVER))
    assert pkt.field == pytest.approx(48.0)


def test_parse_echo_amid_binary_noise():
    data = (b"\x01\x02garbage\nCal1:0.0000,0.0000,0.0000,0.0000,0.0000,0.0000,10.0000,-5.0000,"
            b"2.0000,48.0000\r\n\xff\xfeCal2:1.1000,0.0200,0.0000,0.0200,1.0000,0.0000,0.0000,"
            b"0.0000,0.9000\r\n")
    cal1, cal2 = parse_motioncal_echo(data)
    assert cal1[6:] == [10.0, -5.0, 2.0, 48.0] and cal2[0] == 1.1 and len(cal2) == 9
    assert parse_motioncal_echo(data[:-20]) is None


def test_write_outputs(cal, tmp_path):
    rng = np.random.default_rng(0)
    u = rng.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    pts = cal.accel.offset + u @ np.linalg.inv(cal.accel.matrix).T
    paths = write_outputs(cal, {"accel": pts}, tmp_path, prefix="imu", plot=False)
    assert tc.Calibration.load(paths["json"]) == cal
    assert "imu_accel_apply" in paths["c"].read_text()
    assert "imu_accel_apply_q" in paths["c-fixed"].read_text()
    assert "residual RMS" in paths["report_accel"].read_text()
    assert "motioncal" not in paths  # the fixture's magnetometer matrix is not symmetric


@settings(max_examples=80, deadline=None)
@given(
    off=st.lists(st.floats(-3000, 3000), min_size=3, max_size=3),
    diag=st.lists(st.floats(0.5, 2.0), min_size=3, max_size=3),
    cross=st.lists(st.floats(-0.05, 0.05), min_size=6, max_size=6),
    scale=st.sampled_from([1 / 16384, 1 / 131, 0.15, 1.0, 7.5]),
    raw=st.lists(st.lists(st.integers(-32768, 32767), min_size=3, max_size=3), min_size=1,
                 max_size=20),
)
def test_fixed_point_model_within_one_count_property(off, diag, cross, scale, raw):
    m = np.diag(diag)
    m[0, 1], m[0, 2], m[1, 2], m[1, 0], m[2, 0], m[2, 1] = cross
    part = tc.SensorCalibration(offset=off, matrix=m * scale, unit="x")
    fp = fixed_point(part)
    exact = part.apply(np.array(raw, dtype=float)) * fp.out_scale
    assert np.abs(apply_fixed(fp, raw) - exact).max() <= 1.0


@settings(max_examples=80, deadline=None)
@given(vals=st.lists(st.floats(-1e4, 1e4, width=32), min_size=16, max_size=16))
def test_motioncal_round_trip_property(vals):
    si = np.array([[vals[10], vals[13], vals[14]], [vals[13], vals[11], vals[15]],
                   [vals[14], vals[15], vals[12]]])
    pkt = encode_motioncal(accel_offset=vals[0:3], gyro_offset=vals[3:6], mag_offset=vals[6:9],
                           field=vals[9], soft_iron=si)
    assert decode_motioncal(pkt).values() == vals
