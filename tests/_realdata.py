"""Loaders for the third-party recordings in ../shared/realdata (owned by the imu tests)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def load_imutk_xsens(root: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time (s), accelerometer and gyro raw counts of the imu_tk Xsens MTi recording."""
    acc = np.loadtxt(root / "imutk-xsens" / "xsens_acc.mat")
    gyr = np.loadtxt(root / "imutk-xsens" / "xsens_gyro.mat")
    assert np.array_equal(acc[:, 0], gyr[:, 0])
    return acc[:, 0], acc[:, 1:], gyr[:, 1:]


def load_ferraris_annotated(root: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """imucal's annotated session: {part: (acc counts (N,3), gyro counts (N,3))}, 204.8 Hz."""
    path = root / "imucal-ferraris" / "annotated_session.csv"
    with open(path) as fh:
        header = fh.readline().strip().split(",")
    parts = np.loadtxt(path, delimiter=",", skiprows=1, usecols=0, dtype=str)
    vals = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, len(header)))
    out = {}
    for name in dict.fromkeys(parts.tolist()):
        m = parts == name
        out[name] = (vals[m, 1:4], vals[m, 4:7])
    return out


def load_ferraris_session(root: Path) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[int, int]]]:
    """imucal's continuous session: acc (m/s^2), gyro (deg/s), sections {name: (start, end)}."""
    d = root / "imucal-ferraris"
    vals = np.loadtxt(d / "example_ferraris_session.csv", delimiter=",", skiprows=1)
    sections = json.loads((d / "example_ferraris_session_list.json").read_text())
    sec = {k: (int(v["start"]), int(v["end"])) for k, v in sections.items()}
    return vals[:, 4:7], vals[:, 1:4], sec


def load_gearvr(root: Path, name: str) -> np.ndarray:
    """One freeIMUCal file as an (N, 3) array (units per its README)."""
    return np.loadtxt(root / "freeimucal-gearvr" / name)


def load_sunsided(root: Path, motion: str, sensor: str) -> np.ndarray:
    """One sunsided MPU6050 buffer (t first), zero-filled tail rows dropped."""
    import h5py

    names = {
        "accelerometer": ("mpu6050_accelerometer", "accelBuffer"),
        "gyroscope": ("mpu6050_gyroscope", "gyroBuffer"),
        "temperature": ("mpu6050_temperature", "temperatureBuffer"),
        "compass": ("hmc5883l_compass", "compassBuffer"),
    }
    fname, var = names[sensor]
    with h5py.File(root / "sunsided-mpu6050-hmc5883l" / motion / f"{fname}.mat", "r") as f:
        arr = np.array(f[var]).T
    keep = ~((arr[:, 0] == 0) & (np.arange(len(arr)) > 0))
    return arr[keep]
