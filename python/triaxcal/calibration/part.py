"""One sensor's calibration: :class:`SensorCalibration` (and its temperature terms).

Error model: a raw reading ``raw`` (in ``raw_unit``, usually counts) becomes
``calibrated = (raw - offset) @ matrix.T`` (in ``unit``). ``offset`` is the bias / hard iron in
raw units; ``matrix`` **multiplies** and carries calibrated units per raw unit (scale,
cross-axis, soft iron). Optional temperature terms, in ``dT = T - temp_ref_c`` (deg C):

* ``offset(T) = offset + sum_k offset_poly[k] * dT**k``  (raw units; row 0 is usually zero);
* ``gain(T) = 1 + sum_k gain_poly[k] * dT**k``, per raw axis, which **multiplies** the
  offset-corrected raw reading before the matrix:
  ``calibrated = ((raw - offset(T)) * gain(T)) @ matrix.T``.

A part the validity gate judged (:mod:`triaxcal.calibration.gate`) says so: ``valid`` is True,
or False with ``invalid_reasons`` when it was written anyway (``--force``).
"""

from __future__ import annotations

import contextvars
import datetime as _dt
import hashlib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks.arrays import as_points
from ..conventions.names import AXES, LOWER, UPPER
from ..errors import CalibrationError
from ..methods.field import ExpectedField
from . import schema as _schema
from .alignment import Alignment

__all__ = ["MAX_PREVIOUS", "SensorCalibration", "TemperatureTerms", "sha256_points"]

#: Most summaries of replaced calibrations a part keeps (newest first).
MAX_PREVIOUS = _schema.MAX_PREVIOUS

#: Set while :meth:`SensorCalibration.from_dict` builds a part from values it has just checked
#: (free-form ``stats`` are checked once, not twice: they can be megabytes).
_CHECKED: contextvars.ContextVar[bool] = contextvars.ContextVar("triaxcal_part_checked",
                                                                default=False)

_AXES = AXES
_UPPER = UPPER  # xy, xz, yz
_LOWER = LOWER  # yx, zx, zy


def _now_utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat().replace(
        "+00:00", "Z"
    )


def sha256_points(points: Any) -> str:
    """SHA-256 (hex) of readings as little-endian float64, row-major, shape (N, 3).

    The same readings give the same hash whatever dtype they arrived in (int16 counts and
    their float64 copy agree). For a file, the CLI stores the hash of the file's bytes instead
    (``sha256sum FILE`` gives the same).
    """
    arr = np.ascontiguousarray(as_points(points), dtype="<f8")
    return hashlib.sha256(arr.tobytes()).hexdigest()


def _jsonable(value: Any, what: str) -> Any:
    """Deep-copy ``value`` into plain JSON types (dict/list/str/float/int/bool/None)."""
    return _schema.json_value(value, what)


def _summary(d: Any, what: str) -> dict[str, Any]:
    """A validated, plain-JSON copy of one ``previous`` summary (see the module docstring)."""
    return _schema.summary(d, what)


@dataclass(frozen=True, eq=False)
class TemperatureTerms:
    """Polynomial temperature terms of one sensor part, in ``dT = T - temp_ref_c`` (deg C).

    Attributes
    ----------
    temp_ref_c : float
        Reference temperature in deg C (where the main ``offset`` and ``matrix`` hold).
    temp_range_c : tuple of float
        ``(lowest, highest)`` temperature of the fitting data, deg C; outside it the polynomial
        extrapolates.
    offset_poly : ndarray, shape (degree + 1, 3)
        Offset change in raw units, lowest order first: ``offset(T) = offset +
        sum_k offset_poly[k] * dT**k``.
    gain_poly : ndarray, shape (degree + 1, 3), optional
        Relative gain change per raw axis, lowest order first; ``1 + sum_k gain_poly[k] *
        dT**k`` **multiplies** the offset-corrected raw reading.
    """

    temp_ref_c: float
    temp_range_c: tuple[float, float]
    offset_poly: np.ndarray
    gain_poly: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name, f in _schema.TEMPERATURE_FIELDS.items():
            value = getattr(self, name)
            if value is not None or f.required:
                object.__setattr__(self, name, f.check(value, name))

    def offset_delta(self, temperature: Any) -> np.ndarray:
        """Offset change ``sum_k offset_poly[k] * dT**k`` in raw units, shape (N, 3)."""
        return _horner(self.offset_poly, np.asarray(temperature, float) - self.temp_ref_c)

    def gain(self, temperature: Any) -> np.ndarray:
        """Per-axis gain factor ``1 + sum_k gain_poly[k] * dT**k`` (multiplies), (N, 3)."""
        dt = np.asarray(temperature, float) - self.temp_ref_c
        if self.gain_poly is None:
            return np.ones((dt.size, 3))
        return 1.0 + _horner(self.gain_poly, dt)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "temp_ref_c": self.temp_ref_c,
            "temp_range_c": list(self.temp_range_c),
            "offset_poly": self.offset_poly.tolist(),
        }
        if self.gain_poly is not None:
            d["gain_poly"] = self.gain_poly.tolist()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], what: str = "temperature") -> TemperatureTerms:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationError` when malformed."""
        return cls(**_schema.check_fields(d, _schema.TEMPERATURE_FIELDS, what))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TemperatureTerms) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


def _horner(poly: np.ndarray, dt: np.ndarray) -> np.ndarray:
    dt = np.atleast_1d(dt).reshape(-1, 1)
    acc = np.zeros((dt.shape[0], 3)) + poly[-1]
    for row in poly[-2::-1]:
        acc = acc * dt + row
    return acc

@dataclass(frozen=True, eq=False)
class SensorCalibration:
    """Calibration of one three-axis sensor: ``calibrated = (raw - offset) @ matrix.T``.

    Attributes
    ----------
    offset : ndarray, shape (3,)
        Bias / hard iron, in ``raw_unit``.
    matrix : ndarray, shape (3, 3)
        Gain matrix that **multiplies**, in ``unit`` per ``raw_unit``.
    raw_unit : str
        Unit of raw readings, e.g. ``"counts"``.
    unit : str
        Unit of calibrated readings: ``"g"``, ``"m/s^2"``, ``"deg/s"``, ``"rad/s"``, ``"uT"``...
    radius : float, optional
        Magnitude calibrated readings should have (1 for g, the local field in uT), if known.
    model : str, optional
        Fit model: ``"sphere"``, ``"axis"``, ``"full"`` (or another name for hand-made parts).
    temperature : TemperatureTerms, optional
        Temperature terms; :meth:`apply` then needs the temperature in deg C.
    stats : dict
        Fit statistics (``rms``, ``n``, ``stderr`` by parameter name, ``rejected`` indices,
        norm statistics, coverage...), plain JSON values.
    input_sha256 : str, optional
        SHA-256 of the input data (see :func:`sha256_points`), for provenance.
    source : str, optional
        Where the data came from (a file name), for provenance.
    previous : tuple of dict
        Summaries of the calibrations of this sensor that this one replaced, newest first (see
        :meth:`with_previous`).
    expected_field : ExpectedField, optional
        The field the World Magnetic Model expects where the part was calibrated (magnetometer).
    alignment : Alignment, optional
        Rotation of this part's calibrated frame into another part's (magnetometer into
        accelerometer); :meth:`apply_aligned` applies it.
    valid : bool, optional
        The validity gate's verdict (:func:`triaxcal.calibration.gate.check`): True for a part
        it passed, False for one written anyway (``--force``), None for a part never judged
        (made by hand, or by a version before the gate).
    invalid_reasons : tuple of str
        Why the gate refused it (when ``valid`` is False).
    """

    offset: np.ndarray
    matrix: np.ndarray
    raw_unit: str = "counts"
    unit: str = "counts"
    radius: float | None = None
    model: str | None = None
    temperature: TemperatureTerms | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    input_sha256: str | None = None
    source: str | None = None
    previous: tuple[dict[str, Any], ...] = ()
    expected_field: ExpectedField | None = None
    alignment: Alignment | None = None
    valid: bool | None = None
    invalid_reasons: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        f = _schema.PART_FIELDS
        object.__setattr__(self, "offset", f["offset"].check(self.offset, "offset"))
        matrix = _schema.reals(self.matrix, (3, 3), "matrix")
        _schema.check_matrix(matrix, "matrix")
        object.__setattr__(self, "matrix", matrix)
        for name in ("raw_unit", "unit", "radius", "model", "input_sha256", "source"):
            object.__setattr__(self, name, f[name].check(getattr(self, name), name))
        if self.temperature is not None and not isinstance(self.temperature, TemperatureTerms):
            object.__setattr__(self, "temperature", TemperatureTerms.from_dict(self.temperature))
        if not isinstance(self.stats, Mapping):
            raise CalibrationError(f"stats must be a mapping, got {type(self.stats).__name__}")
        if not _CHECKED.get():  # from_dict has just checked them: not twice
            object.__setattr__(self, "stats", _schema.stats_object(dict(self.stats), "stats"))
        prev = self.previous
        if isinstance(prev, (str, bytes, Mapping)) or not isinstance(prev, (list, tuple)):
            raise CalibrationError("previous must be a list of summaries (newest first)")
        if len(prev) > 10 * MAX_PREVIOUS:
            raise CalibrationError(f"previous holds {len(prev)} summaries; at most "
                                   f"{MAX_PREVIOUS} are kept")
        object.__setattr__(self, "previous", tuple(
            _summary(p, f"previous[{i}]") for i, p in enumerate(prev)))
        if self.expected_field is not None and not isinstance(self.expected_field,
                                                              ExpectedField):
            object.__setattr__(self, "expected_field",
                               ExpectedField.from_dict(self.expected_field))
        if self.alignment is not None and not isinstance(self.alignment, Alignment):
            object.__setattr__(self, "alignment", Alignment.from_dict(self.alignment))
        object.__setattr__(self, "valid", f["valid"].check(self.valid, "valid"))
        reasons = self.invalid_reasons
        if isinstance(reasons, (str, bytes)) or not isinstance(reasons, (list, tuple)):
            raise CalibrationError("invalid_reasons must be a list of text")
        object.__setattr__(self, "invalid_reasons", tuple(
            f["invalid_reasons"].check(list(reasons), "invalid_reasons")))
        if self.invalid_reasons and self.valid is not False:
            raise CalibrationError("invalid_reasons are given, but valid is not false: a part "
                                   "with reasons to refuse it is not valid")

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def from_fit(
        cls,
        fit: Any,
        *,
        raw_unit: str = "counts",
        unit: str | None = None,
        points: Any = None,
        rejected: Any = (),
        temperature: TemperatureTerms | None = None,
        input_sha256: str | None = None,
        source: str | None = None,
        extra_stats: Mapping[str, Any] | None = None,
    ) -> SensorCalibration:
        """Build a part from an :class:`~triaxcal.EllipsoidFit`.

        Parameters
        ----------
        fit : EllipsoidFit
            The fit (``offset``, ``matrix``, ``radius``, ``rms``, ``stderr``...).
        raw_unit : str
            Unit of the fitted readings (default ``"counts"``).
        unit : str, optional
            Unit of calibrated readings, e.g. ``"g"`` when the fit used ``radius=1.0``.
            Defaults to ``raw_unit`` (a fit without a radius keeps the data's scale).
        points : array_like (N, 3), optional
            The raw readings fitted; adds calibrated-norm statistics and, unless
            ``input_sha256`` is given, their hash.
        rejected : sequence of int
            Indices of readings rejected as outliers before the fit (recorded in ``stats``).
        temperature : TemperatureTerms, optional
        input_sha256, source : str, optional
            Provenance.
        extra_stats : mapping, optional
            More statistics to record (e.g. the model-selection reason).

        Examples
        --------
        >>> import numpy as np, triaxcal as tc
        >>> pts = np.array([[2, 0, 0], [0, 0, 0], [1, 1, 0], [1, -1, 0], [1, 0, 1], [1, 0, -1]])
        >>> part = tc.SensorCalibration.from_fit(tc.fit_sphere(pts, radius=1.0), unit="g")
        >>> part.unit, np.round(part.offset, 6).tolist()
        ('g', [1.0, 0.0, 0.0])
        """
        stderr = getattr(fit, "stderr", np.zeros(0))
        names = getattr(fit, "param_names", ())
        stats: dict[str, Any] = {
            "model": fit.model,
            "n": int(fit.n),
            "rms": float(fit.rms),
            "radius": float(fit.radius),
            "rms_pct_of_radius": 100.0 * float(fit.rms) / float(fit.radius),
            "iterations": int(fit.iterations),
            "converged": bool(fit.converged),
            "condition": float(fit.condition) if math.isfinite(fit.condition) else None,
            "stderr": {str(k): float(v) for k, v in zip(names, stderr)},
            "warnings": list(fit.warnings),
            "rejected": [int(i) for i in np.asarray(rejected, dtype=np.int64).ravel()],
        }
        if points is not None:
            pts = as_points(points)
            norms = np.linalg.norm(fit.apply(pts), axis=1)
            stats["norms"] = _norm_stats(norms)
            if input_sha256 is None:
                input_sha256 = sha256_points(pts)
        if extra_stats:
            stats.update(_jsonable(dict(extra_stats), "extra_stats"))
        return cls(
            offset=fit.offset,
            matrix=fit.matrix,
            raw_unit=raw_unit,
            unit=raw_unit if unit is None else unit,
            radius=float(fit.radius),
            model=fit.model,
            temperature=temperature,
            stats=stats,
            input_sha256=input_sha256,
            source=source,
        )

    @classmethod
    def from_temperature_model(
        cls,
        model: Any,
        *,
        raw_unit: str = "counts",
        unit: str = "counts",
        radius: float | None = None,
        source: str | None = None,
        input_sha256: str | None = None,
    ) -> SensorCalibration:
        """Build a part from a :class:`triaxcal.methods.temperature.TemperatureModel`.

        That model reads ``calibrated = inv(S(T)) @ (raw - offset(T))`` with polynomial
        ``offset(T)`` (``offset_coef``) and sensitivity ``S(T)`` (``sens_coef``). Here:
        ``offset = offset_coef[0]``, ``matrix = inv(sens_coef[0])`` (the calibration at
        ``reference_degC``), ``offset_poly = offset_coef`` with row 0 zeroed, and -- when the
        sensitivity changes with temperature -- ``gain_poly``: a least-squares polynomial
        (degree + 1) over the fitted range of the diagonal of ``S(T0) @ inv(S(T)) - 1``, the
        per-raw-axis gain. Off-diagonal drift cannot be held in ``gain_poly``; the largest
        relative error of the approximation over the range is recorded in
        ``stats["temperature_gain_error"]``.
        """
        oc = np.asarray(model.offset_coef, dtype=np.float64)
        sc = np.asarray(model.sens_coef, dtype=np.float64)
        if oc.ndim != 2 or oc.shape[1] != 3 or sc.shape != (oc.shape[0], 3, 3):
            raise CalibrationError(
                "model must have offset_coef (degree + 1, 3) and sens_coef (degree + 1, 3, 3)"
            )
        t0 = float(model.reference_degC)
        lo, hi = float(model.t_min_degC), float(model.t_max_degC)
        s0 = sc[0]
        try:
            m0 = np.linalg.inv(s0)
        except np.linalg.LinAlgError:
            raise CalibrationError("the model's sensitivity at the reference is singular") from None
        opoly = oc.copy()
        opoly[0] = 0.0
        gpoly = None
        stats: dict[str, Any] = {"n": int(getattr(model, "n", 0))}
        if np.any(sc[1:] != 0) and hi > lo:
            ts = np.linspace(lo, hi, 64)
            dts = ts - t0
            powers = dts[:, None] ** np.arange(len(sc))
            sens = np.tensordot(powers, sc, axes=(-1, 0))  # (64, 3, 3)
            rel = s0[None] @ np.linalg.inv(sens)  # (64, 3, 3): diag(g) ideally
            g = np.diagonal(rel, axis1=1, axis2=2) - 1.0
            deg = len(sc)  # model degree + 1
            vander = dts[:, None] ** np.arange(deg + 1)
            coef, *_ = np.linalg.lstsq(vander, g, rcond=None)
            gpoly = coef
            approx = vander @ coef
            full = m0[None] @ (np.eye(3)[None] * (1 + approx)[:, None, :])
            exact = np.linalg.inv(sens)
            err = np.max(np.abs(full - exact)) / np.max(np.abs(m0))
            stats["temperature_gain_error"] = float(err)
        terms = TemperatureTerms(temp_ref_c=t0, temp_range_c=(lo, hi), offset_poly=opoly,
                                 gain_poly=gpoly)
        rms = getattr(model, "rms", None)
        if rms is not None:
            stats["temperature_rms"] = np.asarray(rms, dtype=float).tolist()
        return cls(offset=oc[0], matrix=m0, raw_unit=raw_unit, unit=unit, radius=radius,
                   model=f"temperature-poly{len(oc) - 1}", temperature=terms, stats=stats,
                   source=source, input_sha256=input_sha256)

    # -- use ------------------------------------------------------------------------------
    def apply(self, raw: Any, temperature: Any = None) -> np.ndarray:
        """Calibrate raw readings: ``((raw - offset(T)) * gain(T)) @ matrix.T``.

        Parameters
        ----------
        raw : array_like, shape (N, 3) or (3,)
            Readings in ``raw_unit``.
        temperature : float or array_like (N,), optional
            Sensor temperature in deg C; required when the part has temperature terms (pass
            ``temp_ref_c`` to skip the correction on purpose).

        Returns
        -------
        ndarray
            Calibrated readings in ``unit``, the shape of ``raw``.
        """
        arr = np.asarray(raw)
        single = arr.ndim == 1
        pts = as_points(arr.reshape(1, -1) if single else arr, name="raw")
        if not np.isfinite(pts).all():
            raise CalibrationError("raw readings must be finite (no NaN or inf)")
        d = pts - self.offset
        if self.temperature is not None:
            if temperature is None:
                raise CalibrationError(
                    "this calibration has temperature terms: pass temperature= in deg C (or "
                    f"temperature={self.temperature.temp_ref_c} to skip the correction)"
                )
            t = np.asarray(temperature, dtype=np.float64).ravel()
            if t.size not in (1, pts.shape[0]) or not np.isfinite(t).all():
                raise CalibrationError(
                    f"temperature must be one finite number or one per reading ({pts.shape[0]}),"
                    f" got {t.size} values"
                )
            t = np.broadcast_to(t, (pts.shape[0],))
            d = (d - self.temperature.offset_delta(t)) * self.temperature.gain(t)
        out = d @ self.matrix.T
        return out[0] if single else out

    def apply_aligned(self, raw: Any, temperature: Any = None) -> np.ndarray:
        """Calibrate, then turn into the aligned frame: ``apply(raw) @ alignment.rotation.T``.

        Raises :class:`CalibrationError` when the part has no alignment.
        """
        if self.alignment is None:
            raise CalibrationError(
                "this part has no alignment: fit one with tc.align_mag_accel (or `triaxcal fit "
                "--sensor mag --align`), or use apply()")
        out = self.apply(raw, temperature=temperature)
        return out @ self.alignment.rotation.T

    def replace(self, **changes: Any) -> SensorCalibration:
        """A copy with some fields changed (e.g. ``part.replace(alignment=None)``)."""
        import dataclasses

        return dataclasses.replace(self, **changes)

    @property
    def diag(self) -> np.ndarray:
        """Diagonal of ``matrix`` (per-axis gain), calibrated units per raw unit."""
        return np.diag(self.matrix).copy()

    @property
    def offdiag(self) -> np.ndarray:
        """Upper off-diagonal terms ``[xy, xz, yz]`` of ``matrix``."""
        return np.array([self.matrix[i, j] for i, j in _UPPER])

    @property
    def symmetric(self) -> bool:
        """Whether ``matrix`` is exactly symmetric (as every ellipsoid fit returns)."""
        return all(self.matrix[i, j] == self.matrix[j, i] for i, j in _UPPER)

    # -- history --------------------------------------------------------------------------
    def summary(self, *, replaced_utc: str | None = None, created_utc: str = "") -> dict[str, Any]:
        """What ``previous`` keeps of this part once it is replaced: coefficients, units,
        standard errors, residual RMS and provenance (no temperature terms, no history)."""
        d: dict[str, Any] = {
            "replaced_utc": replaced_utc or _now_utc(),
            "created_utc": created_utc,
            "raw_unit": self.raw_unit,
            "unit": self.unit,
            "offset": self.offset.tolist(),
            "diag": self.diag.tolist(),
            "offdiag": self.offdiag.tolist(),
        }
        if not self.symmetric:
            d["offdiag_lower"] = [float(self.matrix[i, j]) for i, j in _LOWER]
        d["radius"] = self.radius
        d["model"] = self.model
        for k in ("stderr", "rms", "n"):
            if k in self.stats:
                d[k] = self.stats[k]
        d["input_sha256"] = self.input_sha256
        d["source"] = self.source
        return _summary(d, "summary")

    def with_previous(self, old: SensorCalibration, *, created_utc: str = "",
                      replaced_utc: str | None = None) -> SensorCalibration:
        """This part, remembering that it replaced ``old`` (whose file was created at
        ``created_utc``): ``old``'s summary, then ``old``'s own history, newest first, at most
        :data:`MAX_PREVIOUS`."""
        hist = (old.summary(replaced_utc=replaced_utc, created_utc=created_utc),
                *old.previous)
        return self.replace(previous=hist[:MAX_PREVIOUS])

    def previous_part(self, index: int = 0) -> SensorCalibration:
        """The replaced calibration ``previous[index]`` as a part (its standard errors, RMS and
        reading count in ``stats``), e.g. to compare with this one."""
        if not 0 <= index < len(self.previous):
            raise CalibrationError(
                f"this part keeps {len(self.previous)} earlier calibration(s); no "
                f"previous[{index}]"
            )
        p = self.previous[index]
        m = np.diag(p["diag"])
        lower = p.get("offdiag_lower") or p["offdiag"]
        for k, (i, j) in enumerate(_UPPER):
            m[i, j] = p["offdiag"][k]
            m[j, i] = lower[k]
        return SensorCalibration(
            offset=p["offset"], matrix=m, raw_unit=p["raw_unit"], unit=p["unit"],
            radius=p.get("radius"), model=p.get("model"),
            stats={k: p[k] for k in ("stderr", "rms", "n") if k in p},
            input_sha256=p.get("input_sha256"), source=p.get("source"),
        )

    # -- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (the ``parts.<sensor>`` object of the file)."""
        d: dict[str, Any] = {
            "raw_unit": self.raw_unit,
            "unit": self.unit,
            "offset": self.offset.tolist(),
            "diag": self.diag.tolist(),
            "offdiag": self.offdiag.tolist(),
        }
        if not self.symmetric:
            d["offdiag_lower"] = [float(self.matrix[i, j]) for i, j in _LOWER]
        d["radius"] = self.radius
        d["model"] = self.model
        d["temperature"] = None if self.temperature is None else self.temperature.to_dict()
        d["input_sha256"] = self.input_sha256
        d["source"] = self.source
        d["stats"] = self.stats
        if self.previous:
            d["previous"] = [dict(p) for p in self.previous]
        if self.expected_field is not None:
            d["expected_field"] = self.expected_field.to_dict()
        if self.alignment is not None:
            d["alignment"] = self.alignment.to_dict()
        if self.valid is not None:
            d["valid"] = self.valid
        if self.invalid_reasons:
            d["invalid_reasons"] = list(self.invalid_reasons)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], what: str = "part") -> SensorCalibration:
        """Inverse of :meth:`to_dict`; raises :class:`CalibrationError` when malformed."""
        v = _schema.check_fields(d, _schema.PART_FIELDS, what)
        diag, upper = v["diag"], v["offdiag"]
        lower = v.get("offdiag_lower")
        lower = upper if lower is None else lower
        m = np.diag(diag)
        for k, (i, j) in enumerate(_UPPER):
            m[i, j] = upper[k]
            m[j, i] = lower[k]
        _schema.check_matrix(m, what)
        temp = v.get("temperature")
        kw = dict(
            offset=v["offset"],
            matrix=m,
            raw_unit=v["raw_unit"],
            unit=v["unit"],
            radius=v.get("radius"),
            model=v.get("model"),
            temperature=None if temp is None else TemperatureTerms(**temp),
            stats=v.get("stats") or {},
            input_sha256=v.get("input_sha256"),
            source=v.get("source"),
            previous=v.get("previous") or (),
            expected_field=v.get("expected_field"),
            alignment=v.get("alignment"),
            valid=v.get("valid"),
            invalid_reasons=tuple(v.get("invalid_reasons") or ()),
        )
        token = _CHECKED.set(True)
        try:
            return cls(**kw)
        except CalibrationError as exc:
            raise CalibrationError(f"{what}: {exc}") from None
        finally:
            _CHECKED.reset(token)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SensorCalibration) and self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        off = ", ".join(f"{v:.6g}" for v in self.offset)
        diag = ", ".join(f"{v:.6g}" for v in self.diag)
        t = ", temperature" if self.temperature is not None else ""
        return (
            f"SensorCalibration({self.raw_unit} -> {self.unit}, model={self.model!r}, "
            f"offset=[{off}], diag=[{diag}], radius={self.radius}{t})"
        )


def _norm_stats(norms: np.ndarray) -> dict[str, float | None]:
    mean = float(np.mean(norms))
    std = float(np.std(norms, ddof=1)) if norms.size > 1 else 0.0
    return {
        "min": float(np.min(norms)),
        "max": float(np.max(norms)),
        "mean": mean,
        "std": std,
        "std_over_mean": std / mean if mean else None,
    }


