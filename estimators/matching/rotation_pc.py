"""Rotation-aware phase correlation: heading change first, then the paper's translation.

The paper's phase correlation (eqs. 6-9) finds a shift between two scan images (eqs. 4-5) and
so needs scans that share an orientation. Between sensor-frame scans the pipeline here

1. finds the heading change from the images' log-polar magnitude spectra (Fourier-Mellin,
   :mod:`estimators.matching.rotation`), which does not depend on the unknown translation;
2. draws the later scan turned back by that angle and phase-correlates it with the earlier
   one's image (:func:`estimators.paper.phase_correlation.phase_correlate`, subpixel) for the
   translation;
3. optionally polishes the pose with a few ICP iterations started from it -- point-to-curve
   (:mod:`estimators.matching.curve_refinement`) with :mod:`estimators.matching.icp`'s
   Gauss-Newton step -- a correlative-then-refine pipeline as in Olson's and Cartographer's
   matchers: the correlation finds the basin, ICP its bottom. A motion prior from the
   estimator's own increments
   (:func:`estimators.odometry.motion_prior.prediction_information`), held about the car's centre
   rather than the sensor, holds what the scans leave open (corridors).

:class:`ScanMatcher` does one pair of scans (any two sensors); :class:`RotationPhaseCorrelation`
chains the matches of one Lidar's consecutive scans into car poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from estimators.base import Estimator, SensorSetup
from estimators.health import evident_time_step
from estimators.matching.curve_refinement import (
    PRIOR_INFORMATION,
    PRIOR_SIGMA,
    CurveReference,
    covers_full_turn,
    pose_difference,
    refine_on_curves,
)
from estimators.matching.prediction import constant_velocity, within_prediction_horizon
from estimators.matching.rotation import (
    CentredSpectrum,
    centred_spectrum,
    heading_change,
    log_polar_spectrum,
)
from estimators.matching.scan_matching import DEFAULT_MIN_RANGE
from estimators.paper.pc import MIN_MATCH_RETURNS
from estimators.paper.phase_correlation import ImageSpectrum, image_spectrum, phase_correlate
from estimators.paper.scan_image import (
    DEFAULT_SIZE,
    check_image_geometry,
    pixel_shift_to_metres,
    scan_to_image,
)
from lidar_env.core import ConfigError
from lidar_env.core.se2 import compose, inverse, wrap_float

FloatArray = NDArray[np.float64]

#: Lowest confidence a match reports, so that a poor match still counts a little in a fusion.
MIN_CONFIDENCE = 1e-3
#: Log-polar grids (angles over the half turn the magnitude spectrum needs, radii) of the
#: rotation search: half-degree bins when the correlation is the answer, 1-degree bins and
#: fewer radii when a refinement follows (enough to land well within its basin, at a quarter
#: of the cost).
POLAR_GRID = (360, 64)
POLAR_GRID_BEFORE_REFINEMENT = (180, 32)
#: Two refinements whose inlier shares differ by less than this are equally good fits (a
#: featureless corridor fits anywhere along it); the one nearer the prior then wins.
QUALITY_TOLERANCE = 0.02
#: ``PRIOR_SIGMA`` as Python floats, for :func:`refinement_starts`' comparisons
_PRIOR_SIGMA_FLOATS = tuple(PRIOR_SIGMA.tolist())


@dataclass
class PreparedScan:
    """What matching needs of one scan, computed once however often the scan is matched.

    ``ranges`` [m] and ``beam_angles`` [rad] as measured; ``points`` ``(M, 2)`` [m] the
    returns in the sensor frame (smoothed onto their surfaces when ``reference`` is set);
    ``reference`` the scan's surfaces for refinement. The eq.-5 image (``image_size`` [px],
    ``resolution`` [m/px]) and its spectra (log-polar ``polar_grid``: angles, radii) are made
    on first use, since a scan that is only refined never needs them.
    """

    ranges: FloatArray
    beam_angles: FloatArray
    points: FloatArray
    reference: CurveReference | None
    max_range: float
    image_size: int
    resolution: float
    polar_grid: tuple[int, int] = POLAR_GRID

    def image(self, turn: float = 0.0) -> NDArray[np.uint8]:
        """The scan's eq.-5 image, its beams turned by ``turn`` [rad]."""
        return scan_to_image(self.ranges, self.beam_angles, self.max_range, self.image_size,
                             self.resolution, turn)

    @cached_property
    def upright_image(self) -> NDArray[np.uint8]:
        """The scan's eq.-5 image as measured (kept: both spectra below start from it)."""
        return self.image()

    @cached_property
    def polar(self) -> FloatArray:
        """The image's log-polar magnitude spectrum (:func:`log_polar_spectrum`)."""
        n_angles, n_radii = self.polar_grid
        return log_polar_spectrum(self.upright_image, n_angles=n_angles, n_radii=n_radii)

    @cached_property
    def polar_spectrum(self) -> CentredSpectrum:
        """:attr:`polar`'s :func:`centred_spectrum` (a keyframe's serves every later match)."""
        return centred_spectrum(self.polar)

    @cached_property
    def spectrum(self) -> ImageSpectrum:
        """The image's whitened FFT (:func:`image_spectrum`)."""
        return image_spectrum(self.upright_image)


@dataclass(frozen=True)
class ScanMatch:
    """``pose`` (3,): the later sensor's pose (x [m], y [m], heading [rad]) in the earlier
    sensor's frame; ``confidence`` in [MIN_CONFIDENCE, 1]."""

    pose: FloatArray
    confidence: float


def too_few_returns(earlier: PreparedScan, later: PreparedScan) -> bool:
    """Either scan holds fewer than ``MIN_MATCH_RETURNS`` returns: nothing to match (a
    correlation or a fit would put the few points anywhere), so the match reports the prior
    (or no motion) at ``MIN_CONFIDENCE``."""
    return min(len(earlier.points), len(later.points)) < MIN_MATCH_RETURNS


def unmeasured_match(prior: ArrayLike | None) -> ScanMatch:
    """The answer of a match the scans cannot make: the ``prior`` (3,) if any, else no motion,
    at ``MIN_CONFIDENCE``."""
    pose = np.zeros(3) if prior is None else np.asarray(prior, dtype=np.float64).copy()
    return ScanMatch(pose, MIN_CONFIDENCE)


@dataclass(frozen=True)
class ScanMatcher:
    """Rotation-aware phase correlation between two sensor-frame scans.

    Args:
        max_range: [m] of the scans (readings at or beyond it are "no return").
        image_size: [px] side of the eq.-5 images (default 400, the paper's).
        resolution: [m/px]; default ``2 max_range / image_size``, the finest that holds a scan.
        icp_iterations: point-to-curve ICP iterations after the correlation (0: none). A
            handful suffices because the correlation already lands within a pixel or two.
    """

    max_range: float
    image_size: int = DEFAULT_SIZE
    resolution: float | None = None
    icp_iterations: int = 0
    _resolution: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        resolution = check_image_geometry(self.image_size, self.resolution, self.max_range)
        object.__setattr__(self, "_resolution", resolution)
        if isinstance(self.icp_iterations, bool) or not (
            isinstance(self.icp_iterations, (int, np.integer)) and self.icp_iterations >= 0
        ):
            raise ConfigError(
                f"icp_iterations: expected an integer >= 0, got {self.icp_iterations!r}"
            )

    def prepare(self, ranges: ArrayLike, beam_angles: ArrayLike) -> PreparedScan:
        """Precompute a scan ``(n,)`` [m] with beam directions ``(n,)`` [rad] for matching."""
        ranges = np.asarray(ranges, dtype=np.float64)
        angles = np.asarray(beam_angles, dtype=np.float64)
        hit = (ranges < self.max_range) & (ranges > DEFAULT_MIN_RANGE)
        reference = None
        if self.icp_iterations and np.count_nonzero(hit) >= 3:
            reference = CurveReference(ranges, angles, self.max_range)
            points = reference.smoothed
        else:
            points = np.column_stack([ranges[hit] * np.cos(angles[hit]),
                                      ranges[hit] * np.sin(angles[hit])])
        grid = POLAR_GRID_BEFORE_REFINEMENT if self.icp_iterations else POLAR_GRID
        return PreparedScan(
            ranges,
            angles,
            points,
            reference,
            self.max_range,
            self.image_size,
            self._resolution,
            grid,
        )

    def correlate(
        self, earlier: PreparedScan, later: PreparedScan, prior: ArrayLike | None = None
    ) -> ScanMatch:
        """The rotation-aware phase correlation alone: pose of the ``later`` scan's sensor in
        the ``earlier`` scan's sensor frame, good to about a pixel and a log-polar bin.

        ``prior``: a predicted pose (3,); its heading chooses between the two pi-apart spectrum
        candidates (without it the range profiles choose for full-turn scans, else the smaller
        turn wins).
        """
        if too_few_returns(earlier, later):
            return unmeasured_match(prior)
        profiles = None
        if prior is None and covers_full_turn(earlier.beam_angles, later.beam_angles):
            profiles = (earlier.ranges, later.ranges, earlier.beam_angles, self.max_range)
        hint = None if prior is None else float(np.asarray(prior, dtype=np.float64)[2])
        rotation = heading_change(earlier.polar_spectrum, later.polar_spectrum, hint, profiles)
        turned = image_spectrum(later.image(rotation.angle))
        correlation = phase_correlate(earlier.spectrum, turned)
        # The turned later image sees the scene shifted by minus the sensor's translation.
        translation = -pixel_shift_to_metres(correlation.shift, self._resolution)
        pose = np.array([translation[0], translation[1], rotation.angle])
        # Peak-to-runner-up ratio r >= 1 maps to 1 - 1/r: 0 when ambiguous, -> 1 when unique.
        confidence = rotation.confidence * (1.0 - 1.0 / max(correlation.confidence, 1.0))
        return ScanMatch(pose, clipped_confidence(confidence))

    def match(
        self,
        earlier: PreparedScan,
        later: PreparedScan,
        prior: ArrayLike | None = None,
        pivot: ArrayLike | None = None,
        prior_information: FloatArray = PRIOR_INFORMATION,
    ) -> ScanMatch:
        """Pose of the ``later`` scan's sensor in the ``earlier`` scan's sensor frame:
        :meth:`correlate`, then (with ``icp_iterations``) :meth:`refine` from its answer.

        ``prior``: a predicted pose (3,) (e.g. from the estimator's own recent motion). Its
        heading chooses between the two pi-apart spectrum candidates, and the refinement
        uses it as a prior (information ``prior_information``) about the point ``pivot`` (2,) of
        the later sensor's frame (see :func:`refine_on_curves`).
        """
        prior = None if prior is None else np.asarray(prior, dtype=np.float64)
        if too_few_returns(earlier, later):
            return unmeasured_match(prior)
        correlated = self.correlate(earlier, later, prior)
        if earlier.reference is None or len(later.points) < 3:
            return correlated
        return self.refine(
            earlier, later, refinement_starts(correlated.pose, prior), prior, pivot,
            prior_information,
        )

    def refine(
        self,
        earlier: PreparedScan,
        later: PreparedScan,
        starts: list[FloatArray],
        prior: FloatArray | None = None,
        pivot: ArrayLike | None = None,
        prior_information: FloatArray = PRIOR_INFORMATION,
    ) -> ScanMatch:
        """Point-to-curve refinement (:func:`refine_on_curves`) from each of the ``starts``
        (poses of the later sensor in the earlier one's frame); the best fit wins, and among
        fits equally good within ``QUALITY_TOLERANCE`` the one nearest ``prior`` (which holds
        about ``pivot``).
        Needs a matcher with ``icp_iterations > 0``."""
        if too_few_returns(earlier, later):
            return unmeasured_match(prior)
        if earlier.reference is None:
            raise ConfigError("refine: expected a matcher with icp_iterations > 0, got 0")
        refined = [
            refine_on_curves(
                earlier.reference,
                later.points,
                start,
                self.icp_iterations,
                prior,
                pivot,
                prior_information,
            )
            for start in starts
        ]
        best_quality = max(quality for _, quality in refined)
        candidates = [r for r in refined if r[1] >= best_quality - QUALITY_TOLERANCE]
        if prior is not None and len(candidates) > 1:
            candidates.sort(
                key=lambda r: float(np.sum((pose_difference(r[0], prior) / PRIOR_SIGMA) ** 2))
            )
        pose, confidence = candidates[0]
        return ScanMatch(pose, clipped_confidence(confidence))


def clipped_confidence(confidence: float) -> float:
    """``np.clip(confidence, MIN_CONFIDENCE, 1.0)`` of one number (NaN kept), without its cost."""
    return min(max(float(confidence), MIN_CONFIDENCE), 1.0)


def refinement_starts(start: FloatArray, prior: FloatArray | None) -> list[FloatArray]:
    """Where to start refinements: ``start``, and also ``prior`` where the two disagree by more
    than ``PRIOR_SIGMA`` (a correlation fooled by a repetitive scene)."""
    if prior is not None:
        # np.any(|pose_difference(start, prior)| > PRIOR_SIGMA) on the three floats
        (x, y, heading), (x0, y0, heading0) = np.asarray(start).tolist(), np.asarray(prior).tolist()
        sigma_x, sigma_y, sigma_heading = _PRIOR_SIGMA_FLOATS
        if (abs(x - x0) > sigma_x or abs(y - y0) > sigma_y
                or abs(wrap_float(heading - heading0)) > sigma_heading):
            return [start, prior]
    return [start]


def motion_from_sensor_match(mount: ArrayLike, sensor_motion: ArrayLike) -> FloatArray:
    """Car motion ``Δ = mount ⊕ z ⊕ mount⁻¹`` from one sensor's own match ``z`` (same sensor
    at both times)."""
    return compose(compose(mount, sensor_motion), inverse(mount))


def require_sensor_frame(setup: SensorSetup, estimator: str) -> None:
    """Raise unless the scans are in their sensors' own frames, which these estimators need:
    they estimate the heading change from the scans' rotation, and each sensor's pose is the
    car's pose composed with its mount."""
    if setup.world_aligned:
        raise ConfigError(
            f"{estimator}: expected sensor-frame scans (scan_frame='sensor'), got world-aligned "
            "scans; the paper's estimators (pc, pc_pg) take those"
        )


@dataclass
class RotationPhaseCorrelation(Estimator):
    """Car poses from one Lidar's consecutive scans, matched by :class:`ScanMatcher`.

    Each step's sensor motion ``z`` becomes the car motion ``mount ⊕ z ⊕ mount⁻¹``. No
    odometry: the prior handed to the matcher is the previous step's own motion at constant
    velocity (:func:`constant_velocity`). Parameters: ``lidar`` (index into ``setup.keys``:
    0 the main Lidar, 1 the offset one), ``image_size`` [px], ``resolution`` [m/px] (None:
    finest holding ``max_range``), ``icp_iterations``.
    """

    lidar: int = 0
    image_size: int = DEFAULT_SIZE
    resolution: float | None = None
    icp_iterations: int = 0
    _matcher: ScanMatcher | None = field(default=None, init=False, repr=False)
    _previous: PreparedScan | None = field(default=None, init=False, repr=False)
    _last_motion: FloatArray | None = field(default=None, init=False, repr=False)

    @property
    def min_lidars(self) -> int:  # type: ignore[override]  # the offset Lidar needs both
        return self.lidar + 1

    def _used_sensors(self, setup: SensorSetup) -> list[int]:
        valid = not isinstance(self.lidar, bool) and self.lidar in range(setup.n_lidars)
        return [self.lidar] if valid else list(range(setup.n_lidars))
    _last_dt: float = field(default=0.0, init=False, repr=False)

    def _reset_state(self) -> None:
        setup = self._checked_setup()
        require_sensor_frame(setup, type(self).__name__)
        self._matcher = ScanMatcher(
            setup.sensors[self.lidar].max_range, self.image_size, self.resolution,
            self.icp_iterations
        )
        self._previous = None
        self._last_motion = None
        self._last_dt = 0.0

    def _checked_setup(self) -> SensorSetup:
        assert self.setup is not None
        if isinstance(self.lidar, bool) or self.lidar not in range(self.setup.n_lidars):
            raise ConfigError(
                f"lidar: expected an index in 0..{self.setup.n_lidars - 1} "
                f"({', '.join(self.setup.keys)}), got {self.lidar!r}"
            )
        return self.setup

    def _start(self, scans: dict[str, FloatArray], t: float) -> None:
        assert self._matcher is not None and self.setup is not None
        self._previous = self._matcher.prepare(
            scans[self.setup.keys[self.lidar]], self.setup.sensors[self.lidar].beam_angles
        )

    def _step(self, scans: dict[str, FloatArray], t: float) -> FloatArray:
        assert self._matcher is not None and self._previous is not None and self.setup is not None
        current = self._matcher.prepare(scans[self.setup.keys[self.lidar]],
                                        self.setup.sensors[self.lidar].beam_angles)
        dt = t - self._times[-1]
        prior = None
        # past the prediction horizon (a clock gap) the last velocity says nothing: no prior
        if self._last_motion is not None and within_prediction_horizon(dt, [self._last_dt]):
            prior = constant_velocity(self._last_motion, self._last_dt, dt)
        match = self._matcher.match(self._previous, current, prior)
        self._previous = current
        speed = (0.0 if self._last_motion is None or not self._last_dt > 0
                 else float(np.hypot(*self._last_motion[:2])) / self._last_dt)
        self._last_motion = match.pose
        self._last_dt = evident_time_step(float(np.hypot(*match.pose[:2])), speed, dt,
                                          self._last_dt)
        mount = self.setup.mounts[self.lidar]
        return compose(self.pose, motion_from_sensor_match(mount, match.pose))
