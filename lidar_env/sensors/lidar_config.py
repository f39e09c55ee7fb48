"""One Lidar of the env's layout (``EnvConfig.lidars``): its mount, beams, range and noise.

Beam geometry: ``n_beams`` beams spread evenly over ``fov`` [rad], centred on the sensor's
forward axis, angle growing CCW. A full turn (``fov = 2 pi``) has beam ``i`` at ``2 pi i / n``
(beam 0 forward, no beam doubled at +-pi); a narrower Lidar has beam 0 at ``-fov / 2`` and the
last beam at ``+fov / 2`` (``-fov / 2 + fov i / (n - 1)``, as a ROS ``LaserScan`` from
``angle_min`` to ``angle_max``): a 270-degree Lidar's beam 0 points at -135 degrees.

Self-occlusion: by default a Lidar sees over the car (a roof mount). ``self_occlusion=True``
says it sits at body level: the car's rectangle (``car_length x car_width``) is then a wall to
it, except where the outline passes within ``housing_radius`` of the mount (the scanner's window
through the body); a beam meeting the outline farther out reads the distance to it. So a
270-degree Lidar on a corner of the outline, facing out, keeps its whole view; one mounted
5 cm inside both sides of the corner (0.35, 0.2 on the default 0.8 x 0.5 m car) with the
default 0.1 m housing sees 210 degrees, its beams that graze along the two sides reading the
car; a 360-degree one at body level in the car's middle reads only the car.

Valid range: a reading below ``min_range`` is invalid on a real Lidar (ROS: "values < range_min
should be discarded"); the env reports it as ``max_range``, the value of "no return", so a
consumer that drops ``>= max_range`` drops it too, and a bag written from it carries
``range_min`` for ROS tools. ``min_range`` 0 (the default) never triggers.

For the compiled kernel (:mod:`lidar_env.sensors.lidar_layout`), :func:`beam_geometry` sorts a beam
set and :func:`pack_sensors` packs K sensors' beams and parameters end to end.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.core.errors import ConfigError

_TWO_PI = 2.0 * math.pi
#: Most Lidars one car carries.
MAX_LIDARS = 8
#: [rad] a ``fov`` this close to 2 pi is a full turn.
_FULL_TURN_TOLERANCE = 1e-9
#: Most beams one Lidar may cast per scan (real planar Lidars cast up to a few thousand).
MAX_BEAMS = 100_000
#: [m] least and largest ``max_range`` accepted: a float32 reading must resolve it, and no
#: planar Lidar reaches a kilometre.
MIN_MAX_RANGE, MAX_MAX_RANGE = 0.01, 1000.0


@dataclass(frozen=True)
class LidarConfig:
    """One planar Lidar on the car (frozen; units in the field comments).

    The default noise, 0.01 m, is the typical 1 sigma of a cheap time-of-flight Lidar;
    :func:`lidar_env.config.lidars_with_noise` sets the noise of every Lidar of a layout.
    """

    mount: tuple[float, float, float]  # x [m] forward, y [m] left, heading [rad] in the car frame
    n_beams: int = 360  # [-] beams per scan
    fov: float = 2.0 * math.pi  # [rad] field of view, in (0, 2 pi], centred on the forward axis
    max_range: float = 10.0  # [m] a beam that hits nothing reads exactly max_range
    range_noise_std: float = 0.01  # [m] std of the Gaussian noise added to each hit
    dropout_prob: float = 0.0  # [-] probability that a beam reads max_range regardless
    self_occlusion: bool = False  # mounted at body level: the car's own outline blocks beams
    housing_radius: float = 0.1  # [m] the outline within this of the mount does not (window)
    min_range: float = 0.0  # [m] a reading below it is invalid and reads max_range (no return)
    where: str = dataclasses.field(default="lidars[0]", compare=False, repr=False)

    def __post_init__(self) -> None:
        w = self.where
        mount = np.asarray(self.mount, dtype=np.float64) if _is_numeric(self.mount) else None
        if mount is None or mount.shape != (3,) or not np.all(np.isfinite(mount)):
            raise ConfigError(f"{w}.mount: expected 3 finite numbers (x [m], y [m], heading "
                              f"[rad]) in the car frame, got {self.mount!r}")
        n = self.n_beams
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 3 <= n <= MAX_BEAMS:
            raise ConfigError(f"{w}.n_beams: expected an integer in [3, {MAX_BEAMS}], "
                              f"got {_short(n)}")
        if not _finite(self.fov) or not 0 < self.fov <= 2 * math.pi + _FULL_TURN_TOLERANCE:
            raise ConfigError(f"{w}.fov: expected a field of view in (0, 2 pi] [rad], "
                              f"got {self.fov!r}")
        if not _finite(self.max_range) or not MIN_MAX_RANGE <= self.max_range <= MAX_MAX_RANGE:
            raise ConfigError(f"{w}.max_range: expected a number in [{MIN_MAX_RANGE:g}, "
                              f"{MAX_MAX_RANGE:g}] [m], got {_short(self.max_range)}")
        if not _finite(self.min_range) or not 0 <= self.min_range < self.max_range:
            raise ConfigError(f"{w}.min_range: expected a number in [0, max_range) = [0, "
                              f"{float(self.max_range):g}) [m], got {_short(self.min_range)}")
        noise = self.range_noise_std
        if not _finite(noise) or noise < 0:
            raise ConfigError(f"{w}.range_noise_std: expected a finite number >= 0 [m], "
                              f"got {noise!r}")
        drop = self.dropout_prob
        if not _finite(drop) or not 0 <= drop < 1:
            raise ConfigError(f"{w}.dropout_prob: expected a number in [0, 1), got {drop!r}")
        if not isinstance(self.self_occlusion, (bool, np.bool_)):
            raise ConfigError(f"{w}.self_occlusion: expected True or False, "
                              f"got {self.self_occlusion!r}")
        if not _finite(self.housing_radius) or self.housing_radius < 0:
            raise ConfigError(f"{w}.housing_radius: expected a finite number >= 0 [m], "
                              f"got {self.housing_radius!r}")
        object.__setattr__(self, "self_occlusion", bool(self.self_occlusion))
        object.__setattr__(self, "housing_radius", float(self.housing_radius))
        object.__setattr__(self, "mount", tuple(float(v) for v in mount))
        object.__setattr__(self, "n_beams", int(n))
        object.__setattr__(self, "fov", float(self.fov))
        object.__setattr__(self, "max_range", float(self.max_range))
        object.__setattr__(self, "min_range", float(self.min_range))
        object.__setattr__(self, "range_noise_std", float(noise))
        object.__setattr__(self, "dropout_prob", float(drop))

    @classmethod
    def from_value(cls, value: Any, index: int) -> LidarConfig:
        """A ``LidarConfig`` or a dict of its fields (unknown keys named) as ``lidars[index]``."""
        where = f"lidars[{index}]"
        if isinstance(value, LidarConfig):
            return dataclasses.replace(value, where=where)
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a dict of {', '.join(LIDAR_KEYS)}, "
                              f"got {type(value).__name__}")
        unknown = sorted(set(value) - set(LIDAR_KEYS))
        if unknown:
            raise ConfigError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))}: "
                              f"expected some of {', '.join(LIDAR_KEYS)}")
        if "mount" not in value:
            raise ConfigError(f"{where}: expected a 'mount' (x [m], y [m], heading [rad])")
        return cls(**dict(value), where=where)

    def to_dict(self) -> dict[str, Any]:
        """The fields as a plain dict of JSON values (``mount`` a list), so that it compares
        equal after a JSON round trip too; round-trips through :meth:`from_value`."""
        return {**{key: getattr(self, key) for key in LIDAR_KEYS}, "mount": list(self.mount)}

    @property
    def full_turn(self) -> bool:
        """The beams cover the whole circle (``fov`` = 2 pi)."""
        return self.fov >= 2 * math.pi - _FULL_TURN_TOLERANCE

    @cached_property
    def beam_angles(self) -> NDArray[np.float64]:
        """``(n_beams,)`` beam directions [rad] in the sensor frame (see the module docstring)."""
        return self.beam_offset + self.sweep_angles

    @property
    def beam_offset(self) -> float:
        """[rad] direction of beam 0 from the sensor's forward axis: 0 or ``-fov / 2``."""
        return 0.0 if self.full_turn else -0.5 * self.fov

    @cached_property
    def sweep_angles(self) -> NDArray[np.float64]:
        """``(n_beams,)`` beam directions [rad] from beam 0, in ``[0, fov]``, read-only."""
        n = self.n_beams
        if self.full_turn:
            angles = 2.0 * math.pi * np.arange(n) / n
        else:
            angles = self.fov * np.arange(n) / (n - 1)
        angles.flags.writeable = False
        return angles


#: Keys of one entry of ``EnvConfig.lidars``.
LIDAR_KEYS: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(LidarConfig) if f.name != "where"
)


def check_lidars(value: Any, reach: float) -> tuple[LidarConfig, ...]:
    """``value`` (1 to :data:`MAX_LIDARS` dicts or ``LidarConfig``) as checked configs whose
    mounts lie within ``reach`` [m] of the car's centre."""
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__"):
        raise ConfigError(f"lidars: expected a list of 1 to {MAX_LIDARS} dicts, "
                          f"got {type(value).__name__}")
    if not 1 <= len(value) <= MAX_LIDARS:
        raise ConfigError(f"lidars: expected 1 to {MAX_LIDARS} Lidars, got {len(value)}")
    lidars = tuple(LidarConfig.from_value(item, k) for k, item in enumerate(value))
    for lidar in lidars:
        x, y, _ = lidar.mount
        if math.hypot(x, y) > reach + 1e-12:
            raise ConfigError(
                f"{lidar.where}.mount: ({x:g}, {y:g}) lies {math.hypot(x, y):.3f} m from the "
                f"car's centre, outside its reach: expected within the car's half-diagonal "
                f"{reach:.3f} m")
    return lidars


#: Columns of the ``params`` rows of :func:`pack_sensors`: packed beam positions ``[first,
#: end)``, uniform step [rad] (0: not uniform), angle of beam 0 from forward [rad], max range
#: [m], the largest float32 below it, noise std [m], dropout probability, housing radius [m]
#: (negative: no self-occlusion), min range [m], 1.0 when the sensor's beams are in the order of
#: their wrapped angles (``order`` 0, 1, 2, ...: the caster's loops over beams then run over
#: contiguous rows, which the compiler vectorises), else 0.0.
FIRST, END, STEP, OFFSET, MAX_RANGE, BELOW_MAX, NOISE, DROPOUT, HOUSING, MIN_RANGE, IN_ORDER = (
    range(11))
#: Number of those columns.
PARAM_COLUMNS = 11


@njit(cache=True, fastmath=False)
def _beam_order(beam_angles: NDArray[np.float64]) -> tuple:
    """Beam angles wrapped to [0, 2 pi), sorted; their order; and the uniform step (0 if not)."""
    n = beam_angles.shape[0]
    wrapped = np.empty(n)
    for j in range(n):
        wrapped[j] = beam_angles[j] % _TWO_PI
    order = np.argsort(wrapped, kind="mergesort")
    sorted_angles = wrapped[order]
    step = (sorted_angles[n - 1] - sorted_angles[0]) / (n - 1) if n > 1 else 0.0
    uniform = step > 0.0
    for j in range(n):
        if abs(sorted_angles[j] - (sorted_angles[0] + j * step)) > 1e-12 * _TWO_PI:
            uniform = False
            break
    return sorted_angles, order, step if uniform else 0.0


@lru_cache(maxsize=64)
def beam_geometry(angle_bytes: bytes) -> tuple:
    """Sorted wrapped angles, their order, the uniform step (0 if not uniform), cos and sin.

    Cached by the angles' bytes: a Lidar's beams are set up once, not on every scan.
    """
    angles = np.frombuffer(angle_bytes, dtype=np.float64)
    if len(angles) == 0 or not np.all(np.isfinite(angles)):
        raise ConfigError(
            f"beam_angles: expected a non-empty finite 1-D array [rad], got {angles}"
        )
    sorted_angles, order, step = _beam_order(angles)
    return sorted_angles, order, step, np.cos(angles), np.sin(angles)


def pack_sensors(
    sweep_angles: Sequence[NDArray[np.float64]], rows: Sequence[Sequence[float]]
) -> tuple[tuple, NDArray[np.float64]]:
    """The kernel's ``(beams, params)`` for K sensors.

    ``sweep_angles[k]`` are sensor ``k``'s beam directions [rad] from its beam 0, ``rows[k]``
    its ``(offset, max_range, noise_std, dropout_prob, housing_radius, min_range)`` (see
    :data:`OFFSET`).
    ``beams`` is ``(table (6, total): sorted wrapped angles, cos, sin, then three rows of
    work space (exact ranges, beam directions x and y); order (total,))``.
    """
    parts = [beam_geometry(np.ascontiguousarray(a, dtype=np.float64).tobytes())
             for a in sweep_angles]
    sizes = [len(p[0]) for p in parts]
    ends = np.cumsum(sizes)
    table = np.vstack([np.concatenate([p[i] for p in parts]) for i in (0, 3, 4)]
                      + [np.zeros((3, int(ends[-1])))])
    order = np.concatenate([p[1] for p in parts]).astype(np.int64)
    params = np.array([
        (end - size, end, part[2], offset, max_range,
         float(np.nextafter(np.float32(max_range), np.float32(0.0))), noise, drop, housing,
         min_range, float(np.array_equal(part[1], np.arange(size))))
        for part, size, end, (offset, max_range, noise, drop, housing, min_range)
        in zip(parts, sizes, ends, rows, strict=True)], dtype=np.float64)
    return (table, order), params


def _finite(value: Any) -> bool:
    """A real number (not a bool) that is finite as a float (an int past 1e308 is not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _short(value: Any) -> str:
    """``repr(value)`` cut to 40 characters, so a huge number does not flood a message."""
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:37]}..."


def _is_numeric(value: Any) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return False
    return True
