"""ROS 1 (``.bag``) and ROS 2 (sqlite3 ``.db3`` / ``.mcap``) bag reader, with ``rosbags``.

``sensor_msgs/Imu`` gives the accelerometer (``linear_acceleration``, m/s^2) and gyroscope
(``angular_velocity``, rad/s); ``sensor_msgs/MagneticField`` the magnetometer
(``magnetic_field``, tesla, converted to uT); ``sensor_msgs/Temperature`` (deg C), when the bag
has exactly one such topic or one is chosen, becomes the temperature of the IMU streams
(interpolated onto their times). Times are the message ``header.stamp`` (the bag's receive
time when a stamp is zero), in s from the first sample read. ``topic`` chooses among several
topics of a type (one name or several: ``"/imu/data_raw,/imu/mag"``). Whether the driver
calibrated the readings is not recorded in a bag, so streams are marked neither raw nor
calibrated.

A ROS 2 bag is a folder with ``metadata.yaml``; pass the folder or a ``.db3``/``.mcap`` file
in it (a lone ``.mcap`` file also works).

Before ``rosbags`` sees a bag, :func:`~triaxcal.io.logs.bagcheck.check_bag` checks its magic
bytes, that every record's lengths lie inside the file and that every compressed chunk unpacks
to the size it declares (at most 256 MiB): ``rosbags`` would read a file of zeros named
``.bag`` whole into memory, and unpack a chunk without bound.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...errors import CalibrationError
from ..files import check_regular, said
from ..recording import LogRecording, Stream
from . import require
from .bagcheck import check_bag

__all__ = ["read_rosbag"]

_IMU = ("sensor_msgs/msg/Imu", "sensor_msgs/Imu")
_MAG = ("sensor_msgs/msg/MagneticField", "sensor_msgs/MagneticField")
_TEMP = ("sensor_msgs/msg/Temperature", "sensor_msgs/Temperature")


def _topics(topic: Any) -> list[str]:
    if topic is None:
        return []
    items = [topic] if isinstance(topic, str) else list(topic)
    out: list[str] = []
    for item in items:
        if not isinstance(item, str):
            raise CalibrationError(f"--topic must be topic names, got {item!r}")
        out += [t.strip() for t in item.split(",") if t.strip()]
    return out


def _bag_path(p: Path) -> tuple[Path, str]:
    if p.is_dir():
        if not (p / "metadata.yaml").is_file():
            raise CalibrationError(f"{p} is a folder without metadata.yaml: not a ROS 2 bag")
        return p, "ros2-bag"
    check_regular(p, what="log file")
    suffix = p.suffix.lower()
    if suffix == ".bag":
        return p, "ros1-bag"
    if (p.parent / "metadata.yaml").is_file():
        return p.parent, "ros2-bag"
    if suffix == ".mcap":
        return p, "ros2-bag"
    raise CalibrationError(
        f"{p} is a ROS 2 storage file without the bag's metadata.yaml beside it: pass the bag "
        "folder (the one holding metadata.yaml and the .db3 file)"
    )


def _pick(conns: list[Any], types: tuple[str, ...], chosen: list[str], what: str,
          path: Path, required: bool = False) -> Any:
    cands = [c for c in conns if c.msgtype in types]
    if chosen:
        sel = [c for c in cands if c.topic in chosen]
        if len(sel) > 1:
            raise CalibrationError(f"--topic names {len(sel)} {what} topics; name one")
        if sel:
            return sel[0]
        if required:
            have = said(", ".join(sorted(c.topic for c in cands)), 400) or "none"
            raise CalibrationError(f"{path}: none of {', '.join(chosen)} is a {what} topic "
                                   f"({what} topics: {have})")
        return None
    topics = sorted({c.topic for c in cands})
    if len(topics) > 1:
        raise CalibrationError(
            f"{path} has several {what} topics ({said(', '.join(topics), 400)}): choose one "
            "with --topic"
        )
    return cands[0] if cands else None


def read_rosbag(path: str | Path, *, instance: int | None = None, topic: Any = None,
                undo: bool = False) -> LogRecording:
    """Read a ROS 1 or ROS 2 bag; see the module docstring."""
    highlevel = require("rosbags.highlevel", "ROS bags", package="rosbags")
    if instance is not None:
        raise CalibrationError("--instance selects autopilot sensors; in a ROS bag choose the "
                               "sensor with --topic NAME")
    if undo:
        raise CalibrationError(
            "a ROS bag does not record what calibration its driver applied, so there is nothing "
            "triaxcal can undo; drop --undo-autopilot-cal"
        )
    p = Path(path)
    bag, fmt = _bag_path(p)
    check_bag(bag, fmt)  # magic, lengths and chunk sizes, before rosbags sees it
    chosen = _topics(topic)
    try:
        reader = highlevel.AnyReader([bag])
        reader.open()
    except CalibrationError:
        raise
    except Exception as exc:  # rosbags raises its own errors (and OSError) on damaged bags
        raise CalibrationError(
            f"{p} is not a readable ROS bag ({type(exc).__name__}: {said(exc)})"
        ) from None
    try:
        conns = list(reader.connections)
        imu = _pick(conns, _IMU, chosen, "sensor_msgs/Imu", p)
        mag = _pick(conns, _MAG, chosen, "sensor_msgs/MagneticField", p)
        temp = _pick(conns, _TEMP, chosen, "sensor_msgs/Temperature", p)
        known = {c.topic for c in (imu, mag, temp) if c is not None}
        unknown = [t for t in chosen if t not in known]
        have = said(", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in conns})), 400)
        if unknown:
            raise CalibrationError(f"{p}: no Imu, MagneticField or Temperature topic named "
                                   f"{', '.join(unknown)} (topics: {have})")
        if imu is None and mag is None:
            raise CalibrationError(
                f"{p} has no sensor_msgs/Imu or sensor_msgs/MagneticField topic (it has: "
                f"{have or 'none'})"
            )
        sel = [c for c in (imu, mag, temp) if c is not None]
        buf: dict[str, list[tuple[float, float, float, float]]] = {c.topic: [] for c in sel}
        for conn, stamp_ns, raw in reader.messages(connections=sel):
            msg = reader.deserialize(raw, conn.msgtype)
            st = msg.header.stamp
            t = st.sec + st.nanosec * 1e-9 if (st.sec or st.nanosec) else stamp_ns * 1e-9
            if conn is imu:
                a, w = msg.linear_acceleration, msg.angular_velocity
                buf[conn.topic].append((t, a.x, a.y, a.z, w.x, w.y, w.z))  # type: ignore[arg-type]
            elif conn is mag:
                f = msg.magnetic_field
                buf[conn.topic].append((t, f.x, f.y, f.z))
            else:
                buf[conn.topic].append((t, msg.temperature, 0.0, 0.0))
    except CalibrationError:
        raise
    except Exception as exc:
        raise CalibrationError(
            f"{p}: could not read the bag's messages ({type(exc).__name__}: {said(exc)})"
        ) from None
    finally:
        reader.close()
    arrays = {k: np.array(v, dtype=np.float64).reshape(len(v), -1) for k, v in buf.items()}
    starts = [a[:, 0].min() for k, a in arrays.items() if len(a) and (
        k != (temp.topic if temp is not None else None))]
    if not starts:
        raise CalibrationError(f"{p}: the chosen topics hold no messages")
    t0 = min(starts)
    streams: dict[str, Any] = {}
    ta = None
    if temp is not None and len(arrays[temp.topic]) >= 1:
        ta = arrays[temp.topic]
        ta = ta[np.argsort(ta[:, 0], kind="stable")]
    if imu is not None and len(arrays[imu.topic]):
        a = arrays[imu.topic]
        a = a[np.argsort(a[:, 0], kind="stable")]
        t = a[:, 0] - t0
        tc = None if ta is None else np.interp(t, ta[:, 0] - t0, ta[:, 1])
        name = said(imu.topic)
        streams["accel"] = Stream(t=t, data=a[:, 1:4], unit="m/s^2", temp_c=tc, name=name)
        streams["gyro"] = Stream(t=t, data=a[:, 4:7], unit="rad/s", temp_c=tc, name=name)
    if mag is not None and len(arrays[mag.topic]):
        m = arrays[mag.topic]
        m = m[np.argsort(m[:, 0], kind="stable")]
        streams["mag"] = Stream(t=m[:, 0] - t0, data=m[:, 1:4] * 1e6, unit="uT",
                                name=said(mag.topic))
    meta = {"topics": {k: v.name for k, v in streams.items()},
            "temperature_topic": said(temp.topic) if temp is not None else None,
            "all_topics": sorted(said(f"{c.topic} ({c.msgtype})") for c in conns)}
    return LogRecording(**streams, source=str(p), format=fmt, meta=meta)
