"""Scripted motions for the simulated IMU: hold still, turn, hold still (globe, six faces,
rotations, a random tumble)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks.options import seed as seed_of
from ..errors import CalibrationError
from .truth import _ro, matrix_to_rotvec, rotvec_to_matrix

# --------------------------------------------------------------------------------------------
# scripts


@dataclass(frozen=True)
class Script:
    """A scripted sequence of orientations: hold still, turn, hold still, ...

    Attributes
    ----------
    poses : ndarray, shape (P, 3, 3)
        Body-to-world rotation held during pose ``j``.
    rotvecs : ndarray, shape (P, 3)
        Body-frame rotation vector (axis * angle, rad) of the move *into* pose ``j``
        (``rotvecs[0]`` is zero: the script starts at ``poses[0]``). Angles may exceed pi
        (a full turn about an axis).
    move_s : ndarray, shape (P,)
        Duration of the move into pose ``j`` in seconds (``move_s[0]`` is 0).
    hold_s : ndarray, shape (P,)
        Seconds held still at pose ``j`` (``hold_s[0]`` includes the initial rest).
    labels : tuple of str
        One short description per pose.
    """

    poses: np.ndarray
    rotvecs: np.ndarray
    move_s: np.ndarray
    hold_s: np.ndarray
    labels: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def duration_s(self) -> float:
        """Total length of the script in seconds."""
        return float(self.move_s.sum() + self.hold_s.sum())

    @classmethod
    def from_moves(
        cls,
        start: Any,
        rotvecs: Any,
        *,
        hold_s: Any,
        move_s: Any = None,
        peak_dps: float = 120.0,
        min_move_s: float = 0.4,
        labels: Sequence[str] | None = None,
    ) -> Script:
        """Build a script from a start orientation and body-frame moves.

        Parameters
        ----------
        start : array_like (3, 3)
            Body-to-world rotation of pose 0.
        rotvecs : array_like (P - 1, 3)
            Body-frame rotation vectors (rad) of the moves into poses 1..P-1.
        hold_s : float or array_like (P,)
            Seconds still at each pose.
        move_s : float or array_like (P - 1,), optional
            Move durations; by default long enough that the peak rate is ``peak_dps``
            (minimum-jerk profile: peak = 1.875 * angle / duration), at least ``min_move_s``.
        """
        start = np.asarray(start, dtype=np.float64).reshape(3, 3)
        rv = np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)
        p = len(rv) + 1
        angles = np.degrees(np.linalg.norm(rv, axis=1))
        if move_s is None:
            mv = np.maximum(min_move_s, 1.875 * angles / float(peak_dps))
        else:
            mv = np.broadcast_to(np.asarray(move_s, dtype=np.float64), (p - 1,)).copy()
        if np.any(mv <= 0) and len(mv):
            raise CalibrationError("move durations must be > 0 s")
        poses = [start]
        rots = rotvec_to_matrix(rv) if len(rv) else np.zeros((0, 3, 3))
        for r in rots:
            poses.append(poses[-1] @ r)
        hold = np.broadcast_to(np.asarray(hold_s, dtype=np.float64), (p,)).copy()
        if np.any(hold < 0):
            raise CalibrationError("hold durations must be >= 0 s")
        labs = tuple(labels) if labels is not None else tuple(f"pose {i}" for i in range(p))
        if len(labs) != p:
            raise CalibrationError(f"need {p} labels, got {len(labs)}")
        return cls(
            poses=_ro(np.stack(poses)),
            rotvecs=_ro(np.vstack([np.zeros((1, 3)), rv])),
            move_s=_ro(np.concatenate([[0.0], mv])),
            hold_s=_ro(hold),
            labels=labs,
        )

    @classmethod
    def from_poses(
        cls,
        poses: Any,
        *,
        hold_s: Any = 1.0,
        settle_s: float = 2.0,
        peak_dps: float = 120.0,
        min_move_s: float = 0.4,
        labels: Sequence[str] | None = None,
    ) -> Script:
        """Visit body-to-world rotations ``poses`` (P, 3, 3) in order, each by the shortest turn.

        ``settle_s`` seconds of rest are added to the first hold (for detectors that learn the
        noise floor at rest).
        """
        ps = np.asarray(poses, dtype=np.float64).reshape(-1, 3, 3)
        rv = [matrix_to_rotvec(a.T @ b) for a, b in zip(ps[:-1], ps[1:])]
        hold = np.broadcast_to(np.asarray(hold_s, dtype=np.float64), (len(ps),)).copy()
        hold[0] += settle_s
        return cls.from_moves(
            ps[0],
            np.array(rv).reshape(-1, 3),
            hold_s=hold,
            peak_dps=peak_dps,
            min_move_s=min_move_s,
            labels=labels,
        )

    def __add__(self, other: Script) -> Script:
        """Concatenate: after this script's last pose, turn into ``other``'s first pose."""
        if not isinstance(other, Script):
            return NotImplemented
        joint = matrix_to_rotvec(self.poses[-1].T @ other.poses[0])
        angle = math.degrees(float(np.linalg.norm(joint)))
        first = max(0.4, 1.875 * angle / 120.0)
        return Script(
            poses=_ro(np.concatenate([self.poses, other.poses])),
            rotvecs=_ro(np.concatenate([self.rotvecs, [joint], other.rotvecs[1:]])),
            move_s=_ro(np.concatenate([self.move_s, [first], other.move_s[1:]])),
            hold_s=_ro(np.concatenate([self.hold_s, other.hold_s])),
            labels=self.labels + other.labels,
        )


def _frame_from_up(up_body: np.ndarray, heading_rad: float) -> np.ndarray:
    """A body-to-world rotation whose body-frame 'up' is ``up_body``, then turned by heading."""
    up = up_body / np.linalg.norm(up_body)
    # rotation taking body 'up' to world z
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(up, z)
    s, c = np.linalg.norm(axis), float(np.dot(up, z))
    if s < 1e-12:
        base = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        base = rotvec_to_matrix(axis / s * math.atan2(s, c))
    return rotvec_to_matrix(np.array([0.0, 0.0, heading_rad])) @ base


def globe_script(
    *,
    latitudes: int = 7,
    turns: int = 12,
    hold_s: float = 1.0,
    settle_s: float = 2.0,
    peak_dps: float = 120.0,
    azimuth_deg: float = 30.0,
    jitter_deg: float = 2.0,
    seed: int = 0,
) -> Script:
    """The globe scheme: ``latitudes`` points on a meridian x ``turns`` twists = poses.

    The board sits flat on a globe at latitude ``phi`` (from +90 to -90 degrees, evenly
    spaced, poles included) on the meridian facing ``azimuth_deg`` (degrees from north towards
    west), body z along the surface normal, and is twisted about its own z axis in
    ``360 / turns`` degree steps, snaking so that each move is one step. The default gives
    7 x 12 = 84 poses; the body-frame 'up' vector is
    ``(cos phi cos psi, cos phi sin psi, sin phi)``. ``jitter_deg`` adds a random tilt to each
    pose, as placing a board by hand does.
    """
    if latitudes < 2 or turns < 1:
        raise CalibrationError("globe_script needs latitudes >= 2 and turns >= 1")
    rng = np.random.default_rng(seed_of(seed))
    az = math.radians(azimuth_deg)
    poses, labels = [], []
    for i, phi_deg in enumerate(np.linspace(90.0, -90.0, latitudes)):
        phi = math.radians(phi_deg)
        n = np.array([math.cos(phi) * math.cos(az), math.cos(phi) * math.sin(az), math.sin(phi)])
        sp = math.sin(phi)
        e_n = np.array([-sp * math.cos(az), -sp * math.sin(az), math.cos(phi)])
        e_e = np.cross(e_n, n)
        order = range(turns) if i % 2 == 0 else range(turns - 1, -1, -1)
        for j in order:
            psi = 2.0 * math.pi * j / turns
            bx = math.cos(psi) * e_n + math.sin(psi) * e_e
            by = np.cross(n, bx)
            rot = np.column_stack([bx, by, n])  # body axes in world coordinates
            if jitter_deg:
                rot = rot @ rotvec_to_matrix(rng.normal(0.0, math.radians(jitter_deg), 3))
            poses.append(rot)
            labels.append(f"latitude {phi_deg:+.0f} deg, twist {math.degrees(psi):.0f} deg")
    return Script.from_poses(
        np.array(poses), hold_s=hold_s, settle_s=settle_s, peak_dps=peak_dps, labels=labels
    )


def tumble_script(n: int, *, seed: int = 0, hold_s: float = 0.5) -> Script:
    """``n`` orientations drawn uniformly at random (unit quaternions), held ``hold_s`` each: a
    board tumbled by hand through the whole sphere.

    >>> s = tumble_script(30, seed=1)
    >>> len(s), bool(abs(s.poses[:, :, 2].mean(axis=0)).max() < 0.4)  # body z all round
    (30, True)
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise CalibrationError(f"tumble_script needs n >= 1 orientations, got {n!r}")
    q = np.random.default_rng([seed_of(seed), 7]).normal(size=(n, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    rot = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)
    return Script.from_poses(rot, hold_s=hold_s, settle_s=0.0)


def six_face_script(
    *,
    hold_s: float = 2.0,
    settle_s: float = 2.0,
    peak_dps: float = 120.0,
    jitter_deg: float = 2.0,
    seed: int = 0,
) -> Script:
    """Six poses, each body axis pointing up then down: +z, -z, +x, -x, +y, -y up.

    Each pose gets a random heading and a tilt of ``jitter_deg`` (rms).
    """
    rng = np.random.default_rng(seed_of(seed))
    ups = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]
    names = ["+Z up", "-Z up", "+X up", "-X up", "+Y up", "-Y up"]
    poses = []
    for up in ups:
        rot = _frame_from_up(np.array(up, dtype=float), rng.uniform(0, 2 * math.pi))
        if jitter_deg:
            rot = rot @ rotvec_to_matrix(rng.normal(0.0, math.radians(jitter_deg), 3))
        poses.append(rot)
    return Script.from_poses(
        np.array(poses), hold_s=hold_s, settle_s=settle_s, peak_dps=peak_dps, labels=names
    )


def rotation_script(
    axis: str | Sequence[float] = "xyz",
    angle_deg: float = 360.0,
    *,
    hold_s: float = 1.0,
    settle_s: float = 2.0,
    peak_dps: float = 180.0,
    start: Any = None,
) -> Script:
    """Turns about body axes by ``+angle_deg`` then ``-angle_deg``, with rests in between.

    For gyroscope gain calibration: integrating the gyro over each turn must give
    ``angle_deg``. ``axis`` is a string of axis letters (``"x"``, ``"xyz"``, ``"-z"``...) or a
    3-vector (one axis). ``start`` is the body-to-world rotation of the first rest (default:
    flat, body z up). Peak rate ``peak_dps`` (keep below the gyro's 250 deg/s range).
    """
    unit = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
    axes: list[np.ndarray] = []
    names: list[str] = []
    if isinstance(axis, str):
        sign = 1.0
        for ch in axis.lower():
            if ch in "+-":
                sign = -1.0 if ch == "-" else 1.0
                continue
            if ch not in unit:
                raise CalibrationError(f"axis letters must be x, y or z, got {axis!r}")
            axes.append(sign * np.array(unit[ch]))
            names.append(("-" if sign < 0 else "") + ch)
            sign = 1.0
    else:
        v = np.asarray(axis, dtype=np.float64).reshape(3)
        if not np.linalg.norm(v) > 0:
            raise CalibrationError("rotation axis must be a non-zero 3-vector")
        axes.append(v / np.linalg.norm(v))
        names.append("axis")
    if not axes:
        raise CalibrationError("rotation_script needs at least one axis")
    ang = math.radians(angle_deg)
    rvs, labels = [], ["rest"]
    for a, nm in zip(axes, names):
        rvs += [a * ang, -a * ang]
        labels += [f"after {nm} {angle_deg:+g} deg", f"after {nm} {-angle_deg:+g} deg"]
    hold = np.full(len(rvs) + 1, float(hold_s))
    hold[0] += settle_s
    return Script.from_moves(
        np.eye(3) if start is None else start,
        np.array(rvs),
        hold_s=hold,
        peak_dps=peak_dps,
        labels=labels,
    )
