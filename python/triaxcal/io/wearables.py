"""Wearable accelerometer files in: Axivity ``.cwa``, GENEActiv ``.bin``, ActiGraph ``.gt3x``.

The readers are the maintained packages' (``pip install 'triaxcal[wearables]'``):

* Axivity AX3 / AX6 ``.cwa`` -- ``scikit-digital-health`` (``skdh.io.ReadCwa``);
* GENEActiv ``.bin`` -- ``skdh.io.ReadBin``; its text header (device, serial, the maker's
  factory calibration) is parsed here, and a file too short or cut off for skdh (it refuses
  fewer than 3600 samples) is decoded page by page here: each page is a text block whose last
  line holds 300 samples of 12 hex digits, x, y, z as 12-bit two's complement counts, then
  10 bits of light, the button and a reserved bit;
* ActiGraph ``.gt3x`` -- ``pygt3x`` (ActiGraph's own reader).

Every reader returns a :class:`WearableRecording` with the acceleration in g as the device's
maker calibrated it (that is the input :func:`triaxcal.autocalibrate` expects), the sample
rate, the time stamps and the temperature when the device records one.

GENEActiv factory calibration (header ``Calibration Data``): ``g = (raw * 100 - offset) /
gain`` per axis, raw in counts. In triaxcal's convention that is ``g = (raw - offset / 100) *
(100 / gain)``: :attr:`WearableRecording.factory` is a :class:`~triaxcal.SensorCalibration`
with ``offset = offset / 100`` counts and ``matrix = diag(100 / gain)`` g per count (the matrix
**multiplies**).
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration.part import SensorCalibration
from ..errors import CalibrationError

__all__ = ["WearableRecording", "geneactiv_header", "read_geneactiv_pages", "read_wearable"]

FORMATS = {".cwa": "Axivity", ".bin": "GENEActiv", ".gt3x": "ActiGraph"}
#: Samples per GENEActiv data page.
PAGE_SAMPLES = 300


@dataclass(frozen=True)
class WearableRecording:
    """A wearable's recording.

    ``acc_g`` (N, 3) acceleration in g (maker-calibrated); ``rate_hz``; ``time_s`` (N,) Unix
    seconds or ``None``; ``temp_c`` (N,) degC or ``None``; ``device`` e.g. ``"GENEActiv 1.1"``;
    ``serial``; ``reader`` the package that decoded the samples; ``factory`` the maker's
    calibration when the file holds it (GENEActiv); ``raw_counts`` (N, 3) when decoded here;
    ``meta`` everything else read from the header.
    """

    path: Path
    acc_g: np.ndarray
    rate_hz: float
    time_s: np.ndarray | None
    temp_c: np.ndarray | None
    device: str
    serial: str | None
    reader: str
    factory: SensorCalibration | None = None
    raw_counts: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.acc_g)

    @property
    def hours(self) -> float:
        return len(self.acc_g) / self.rate_hz / 3600.0


def _need(module: str) -> Any:
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise CalibrationError(
            f"reading wearable files needs {module.split('.')[0]}: pip install "
            "'triaxcal[wearables]'"
        ) from None


def read_wearable(path: Any) -> WearableRecording:
    """Read an Axivity ``.cwa``, GENEActiv ``.bin`` or ActiGraph ``.gt3x`` file.

    Examples
    --------
    >>> rec = read_wearable("ax3.cwa")  # doctest: +SKIP
    >>> rec.acc_g.shape, rec.rate_hz, rec.device  # doctest: +SKIP
    ((17400, 3), 100.0, 'Axivity AX3')
    """
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"wearable file {p} not found")
    kind = FORMATS.get(p.suffix.lower())
    if kind is None:
        raise CalibrationError(
            f"{p.name}: unknown wearable format {p.suffix!r}; triaxcal reads "
            + ", ".join(f"{v} {k}" for k, v in FORMATS.items()))
    if kind == "Axivity":
        return _read_cwa(p)
    if kind == "GENEActiv":
        return _read_geneactiv(p)
    return _read_gt3x(p)


@contextlib.contextmanager
def _quiet() -> Any:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught


def _read_cwa(p: Path) -> WearableRecording:
    io = _need("skdh.io")
    with _quiet() as caught:
        try:
            r = io.ReadCwa().predict(file=str(p))
        except Exception as exc:  # noqa: BLE001 - the reader raises many kinds
            raise CalibrationError(f"{p.name} is not a readable Axivity .cwa file: {exc}") from None
    acc = np.asarray(r.get("accel"), dtype=np.float64)
    if acc.ndim != 2 or acc.shape[1] != 3 or len(acc) == 0:
        raise CalibrationError(f"{p.name}: no acceleration samples in the file")
    with open(p, "rb") as f:
        head = f.read(64)
    serial = None
    if head[:2] == b"MD" and len(head) >= 13:  # deviceId @5 (u16), upperDeviceId @11 (u16)
        upper = int.from_bytes(head[11:13], "little")
        serial = str(((0 if upper == 0xFFFF else upper) << 16)
                     | int.from_bytes(head[5:7], "little"))
    device = "Axivity AX6" if "gyro" in r else "Axivity AX3"
    temp = r.get("temperature")
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=float(r["fs"]), time_s=np.asarray(r["time"], np.float64),
        temp_c=None if temp is None else np.asarray(temp, np.float64), device=device,
        serial=serial, reader="scikit-digital-health ReadCwa",
        meta={"warnings": [str(w.message) for w in caught], "has_gyro": "gyro" in r})


def geneactiv_header(path: Any) -> dict[str, str]:
    """The text header of a GENEActiv ``.bin`` file (up to ``Recorded Data``) as key: value."""
    p = Path(path)
    out: dict[str, str] = {}
    with open(p, encoding="latin-1", newline=None) as f:
        for n, line in enumerate(f):
            line = line.strip()
            if line == "Recorded Data" or n > 200:
                break
            key, sep, value = line.partition(":")
            if sep and key.strip():
                out.setdefault(key.strip(), value.strip())
    if "Device Type" not in out or not out["Device Type"].startswith("GENEActiv"):
        raise CalibrationError(f"{p.name} is not a GENEActiv .bin file (no GENEActiv header)")
    return out


def _factory(header: dict[str, str], source: str) -> SensorCalibration:
    try:
        gain = np.array([float(header[f"{a} gain"]) for a in "xyz"])
        off = np.array([float(header[f"{a} offset"]) for a in "xyz"])
    except (KeyError, ValueError):
        raise CalibrationError("the GENEActiv header has no usable Calibration Data") from None
    if not np.all(np.isfinite(gain)) or np.any(gain <= 0) or not np.all(np.isfinite(off)):
        raise CalibrationError(f"implausible GENEActiv calibration: gains {gain}, offsets {off}")
    return SensorCalibration(offset=off / 100.0, matrix=np.diag(100.0 / gain), raw_unit="counts",
                             unit="g", radius=1.0, model="factory",
                             stats={"calibration_date": header.get("Calibration Date", "")},
                             source=source)


def read_geneactiv_pages(path: Any) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Decode the data pages of a GENEActiv ``.bin``: ``(counts (N, 3) int, temp_c (N,),
    rate_hz, pages)``. A page cut short (a truncated file) and everything after it is left
    out."""
    p = Path(path)
    counts, temps, rate, pages = [], [], 0.0, 0
    with open(p, encoding="latin-1", newline=None) as f:
        lines = [ln.strip() for ln in f]
    i = next((k for k, ln in enumerate(lines) if ln == "Recorded Data"), None)
    while i is not None and i + 9 < len(lines):
        block = lines[i + 1:i + 9]
        data = lines[i + 9]
        meta = {k.strip(): v.strip() for k, _, v in (ln.partition(":") for ln in block)}
        try:
            t = float(meta["Temperature"])
            rate = float(meta["Measurement Frequency"])
        except (KeyError, ValueError):
            break
        if len(data) != 12 * PAGE_SAMPLES or not all(c in "0123456789ABCDEFabcdef"
                                                     for c in data):
            break  # cut off, or not a data line
        words = np.array([int(data[k:k + 12], 16) for k in range(0, len(data), 12)],
                         dtype=np.int64)
        xyz = np.stack([(words >> 36) & 0xFFF, (words >> 24) & 0xFFF, (words >> 12) & 0xFFF],
                       axis=1)
        xyz = np.where(xyz >= 2048, xyz - 4096, xyz)
        counts.append(xyz)
        temps.append(np.full(len(xyz), t))
        pages += 1
        nxt = i + 10
        i = nxt if nxt < len(lines) and lines[nxt] == "Recorded Data" else None
    if not counts:
        raise CalibrationError(f"{p.name}: no complete data page")
    return np.concatenate(counts), np.concatenate(temps), rate, pages


def _read_geneactiv(p: Path) -> WearableRecording:
    header = geneactiv_header(p)
    factory = _factory(header, str(p))
    device = f"GENEActiv {header.get('Device Model', '')}".strip()
    serial = header.get("Device Unique Serial Code") or None
    io = _need("skdh.io")
    with _quiet() as caught:
        try:
            r = io.ReadBin().predict(file=str(p))
            acc = np.asarray(r["accel"], dtype=np.float64)
            return WearableRecording(
                path=p, acc_g=acc, rate_hz=float(r["fs"]),
                time_s=np.asarray(r["time"], np.float64),
                temp_c=np.asarray(r["temperature"], np.float64) if "temperature" in r else None,
                device=device, serial=serial, reader="scikit-digital-health ReadBin",
                factory=factory, meta={"header": header,
                                       "warnings": [str(w.message) for w in caught]})
        except Exception as exc:  # noqa: BLE001 - fall back to the page decoder below
            why = f"{type(exc).__name__}: {exc}"
    counts, temp, rate, pages = read_geneactiv_pages(p)
    acc = factory.apply(counts.astype(np.float64))
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=rate, time_s=None, temp_c=temp, device=device,
        serial=serial, reader="triaxcal GENEActiv page decoder", factory=factory,
        raw_counts=counts, meta={"header": header, "pages": pages,
                                 "skdh_refused": why})


def _read_gt3x(p: Path) -> WearableRecording:
    reader = _need("pygt3x.reader")
    with _quiet() as caught:
        try:
            with reader.FileReader(str(p)) as f:
                info = f.info
                df = f.to_pandas()
        except Exception as exc:  # noqa: BLE001 - the reader raises many kinds
            raise CalibrationError(f"{p.name} is not a readable ActiGraph .gt3x file: {exc}"
                                   ) from None
    acc = df[["X", "Y", "Z"]].to_numpy(dtype=np.float64)
    meta = {"idle_sleep_rows": int(df["IdleSleepMode"].sum()) if "IdleSleepMode" in df else 0,
            "range_g": (info.acceleration_min, info.acceleration_max),
            "scale": info.acceleration_scale, "firmware": info.firmware,
            "warnings": [str(w.message) for w in caught]}
    return WearableRecording(
        path=p, acc_g=acc, rate_hz=float(info.sample_rate),
        time_s=np.asarray(df.index, dtype=np.float64), temp_c=None,
        device=f"ActiGraph {info.device_type}", serial=info.serial_number,
        reader="pygt3x FileReader", meta=meta)
