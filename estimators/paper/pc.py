"""The paper's estimators, as registered for Table I, and the ``zero`` floor.

* ``pc``: main Lidar only, filter + phase correlation ("functions 1 and 2").
* ``pc_offset``: the same on the offset Lidar ("functions 1 and 2 offsets").
* ``pc_pg``: both Lidars + pose-graph correlation, eq. 10 ("functions 1, 2 and 3").
* ``zero``: the car never moves; the floor every leaderboard needs.

Faithful to the paper, the phase-correlation estimators estimate translation only: the
heading stays at the initial one, and each step's translation is measured in the axes of the
scan images, which are assumed not to rotate. With world-aligned scans (the paper's
simplification) that is exact and the trajectory's axes are the world's, so ``initial_pose``
must then be given in world coordinates. With sensor-frame scans the image axes are those of
the first scan; any turn of the car goes unnoticed and bends the estimate away from the truth:
the method's documented weakness, kept on purpose.

Steps are integrated from the initial pose (the paper starts at (0, 0)): the car translates as
its Lidar does, because its heading is held constant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from estimators.base import Estimator, SensorSetup
from estimators.paper.phase_correlation import ImageSpectrum, image_spectrum, phase_correlate
from estimators.paper.pose_graph_correlation import pose_graph_correlation
from estimators.paper.scan_image import (
    DEFAULT_SIZE,
    check_image_geometry,
    check_image_size,
    pixel_shift_to_metres,
    scan_to_image,
)
from lidar_env.core import ConfigError, EstimatorInputError

Scans = dict[str, NDArray[np.float64]]

#: Fewest returns (readings in (0, max_range)) a scan must hold to be matched: with fewer, a
#: correlation or a fit is free to put the few points anywhere (3 returns made ``pc_offset``
#: jump 9.6 m), so the step reports no motion and the last good scan stays the reference.
MIN_MATCH_RETURNS = 10


def _rotation(angle: float) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


@dataclass
class ZeroMotion(Estimator):
    """``zero``: every pose is the initial pose."""

    def _start(self, scans: Scans, t: float) -> None:
        """Nothing to remember."""

    def _step(self, scans: Scans, t: float) -> NDArray[np.float64]:
        return self._initial_pose.copy()


@dataclass
class _ImageCorrelationEstimator(Estimator):
    """Shared by the paper's estimators: scans -> images -> spectra -> translations.

    Args:
        image_size: side of the scan images [px], positive and even (paper default 400).
        resolution: [m/px]; ``None`` = ``2 max_range / image_size``, the finest that holds
            every return (0.05 m/px for 10 m and 400 px).
        subpixel: refine the correlation peak below one pixel (see ``phase_correlate``).
    """

    image_size: int = DEFAULT_SIZE
    resolution: float | None = None
    subpixel: bool = True

    def __post_init__(self) -> None:
        check_image_size(self.image_size)

    def _used_lidars(self) -> tuple[int, ...]:
        """The Lidars this estimator reads (they must share one beam geometry)."""
        assert self.setup is not None
        return tuple(range(min(self.setup.n_lidars, 2)))

    def _reset_state(self) -> None:
        assert self.setup is not None
        missing = [k for k in self._used_lidars() if k >= self.setup.n_lidars]
        if missing:
            raise EstimatorInputError(
                f"lidar {missing[0]} requested but the setup has {self.setup.n_lidars} Lidar(s)")
        used = [self.setup.sensors[k] for k in self._used_lidars()]
        self._geometry = used[0]
        if any(not np.array_equal(s.beam_angles, used[0].beam_angles)
               or s.max_range != used[0].max_range for s in used[1:]):
            raise EstimatorInputError(
                f"{type(self).__name__}: the Lidars it reads ({', '.join(s.name for s in used)}) "
                "differ in beam geometry; expected one beam layout and max range for both")
        self._pixel_size = check_image_geometry(
            self.image_size, self.resolution, self._geometry.max_range
        )
        self._position = self._initial_pose[:2].copy()
        # made once per reset: the beams turned by each rotation drawn, each axes' rotation
        self._turned_beams: dict[float, NDArray[np.float64]] = {}
        self._axes_rotations: dict[float, NDArray[np.float64]] = {}

    def _image_axes_heading(self, lidar: int) -> float:
        """Heading [rad] of the scan-image axes of Lidar ``lidar`` in the trajectory frame."""
        assert self.setup is not None
        if self.setup.world_aligned:
            return 0.0
        return float(self._initial_pose[2] + self.setup.mounts[lidar, 2])

    def _spectrum(self, scan: NDArray[np.float64], rotation: float = 0.0) -> ImageSpectrum:
        """Whitened spectrum of a scan's image, its points rotated by ``rotation`` [rad]."""
        assert self.setup is not None
        beams = self._turned_beams.get(rotation)
        if beams is None:
            beams = self._turned_beams[rotation] = self._geometry.beam_angles + rotation
        image = scan_to_image(
            scan,
            beams,
            self._geometry.max_range,
            self.image_size,
            self._pixel_size,
        )
        return image_spectrum(image)

    def _sensor_motion(self, past: ImageSpectrum, present: ImageSpectrum) -> NDArray[np.float64]:
        """Translation [m] of the sensor between two scans, in image axes: the scene moves the
        opposite way (eq. 6)."""
        shift = phase_correlate(past, present, subpixel=self.subpixel).shift
        return -pixel_shift_to_metres(shift, self._pixel_size)

    def _enough_returns(self, *scans: NDArray[np.float64]) -> bool:
        """Every scan holds at least ``MIN_MATCH_RETURNS`` returns."""
        limit = self._geometry.max_range
        return all(
            np.count_nonzero((scan > 0) & (scan < limit)) >= MIN_MATCH_RETURNS for scan in scans
        )

    def _advance(self, motion: NDArray[np.float64], axes_heading: float) -> NDArray[np.float64]:
        """Add a translation given in image axes to the car position; return the car pose."""
        rotation = self._axes_rotations.get(axes_heading)
        if rotation is None:
            rotation = self._axes_rotations[axes_heading] = _rotation(axes_heading)
        self._position = self._position + rotation @ motion
        return np.array([*self._position, self._initial_pose[2]])


@dataclass
class PhaseCorrelationOdometry(_ImageCorrelationEstimator):
    """``pc`` (``lidar=0``) and ``pc_offset`` (``lidar=1``): one Lidar, eqs. 4-9 per step.

    Args:
        lidar: index of the Lidar used (0 main, 1 offset), as in ``SensorSetup.keys``.
    """

    lidar: int = 0

    @property
    def min_lidars(self) -> int:  # type: ignore[override]  # the offset Lidar needs both
        return self.lidar + 1

    def _used_lidars(self) -> tuple[int, ...]:
        return (self.lidar,)

    def _used_sensors(self, setup: SensorSetup) -> list[int]:
        return [self.lidar] if self.lidar < setup.n_lidars else list(range(setup.n_lidars))

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.lidar not in (0, 1):
            raise ConfigError(f"lidar: expected 0 (main) or 1 (offset), got {self.lidar!r}")

    def _reset_state(self) -> None:
        super()._reset_state()
        assert self.setup is not None
        self._key = self.setup.keys[self.lidar]
        self._axes_heading = self._image_axes_heading(self.lidar)

    def _start(self, scans: Scans, t: float) -> None:
        self._past = self._spectrum(scans[self._key])
        self._past_usable = self._enough_returns(scans[self._key])

    def _step(self, scans: Scans, t: float) -> NDArray[np.float64]:
        if not self._enough_returns(scans[self._key]):
            return self._advance(np.zeros(2), self._axes_heading)  # no update
        present = self._spectrum(scans[self._key])
        # after a scan too sparse to match, the first good one is the new reference
        motion = self._sensor_motion(self._past, present) if self._past_usable else np.zeros(2)
        self._past, self._past_usable = present, True
        return self._advance(motion, self._axes_heading)


@dataclass
class PoseGraphCorrelationOdometry(_ImageCorrelationEstimator):
    """``pc_pg``: both Lidars, the cross-Lidar estimates fused by eq. 10 every step.

    Both scans are imaged in the main Lidar's axes, each centred on its own Lidar; the known
    main -> offset mount offset, in those axes, is the same at every scan because the heading
    is held constant (so eq. 10's error vector is zero here; see ``pose_graph_correlation``).
    """

    min_lidars: ClassVar[int] = 2

    def _reset_state(self) -> None:
        super()._reset_state()
        assert self.setup is not None
        if self.setup.n_lidars != 2:
            raise EstimatorInputError(f"pc_pg needs 2 Lidars, the setup has {self.setup.n_lidars}")
        main, offset = self.setup.mounts
        self._axes_heading = self._image_axes_heading(0)
        if self.setup.world_aligned:
            self._offset_rotation = 0.0
            self._offset = _rotation(self._initial_pose[2]) @ (offset[:2] - main[:2])
        else:
            self._offset_rotation = float(offset[2] - main[2])
            self._offset = _rotation(-main[2]) @ (offset[:2] - main[:2])

    def _spectra(self, scans: Scans) -> tuple[ImageSpectrum, ImageSpectrum]:
        assert self.setup is not None
        main_key, offset_key = self.setup.keys
        return (
            self._spectrum(scans[main_key]),
            self._spectrum(scans[offset_key], self._offset_rotation),
        )

    def _start(self, scans: Scans, t: float) -> None:
        assert self.setup is not None
        self._past_main, self._past_offset = self._spectra(scans)
        self._past_usable = self._enough_returns(*(scans[key] for key in self.setup.keys))

    def _step(self, scans: Scans, t: float) -> NDArray[np.float64]:
        assert self.setup is not None
        if not self._enough_returns(*(scans[key] for key in self.setup.keys)):
            return self._advance(np.zeros(2), self._axes_heading)  # no update
        main, offset = self._spectra(scans)
        motion = np.zeros(2)  # after a scan too sparse to match: the new reference
        if self._past_usable:
            xi14 = self._sensor_motion(self._past_main, offset)  # P1 -> P4
            xi32 = self._sensor_motion(main, self._past_offset)  # P3 -> P2
            motion = pose_graph_correlation(xi14, xi32, self._offset, self._offset).motion  # eq. 10
        self._past_main, self._past_offset, self._past_usable = main, offset, True
        return self._advance(motion, self._axes_heading)
