"""Rotation-aware phase correlation: heading change first, then the paper's translation.

The paper's phase correlation (eqs. 6-9) finds a shift between two scan images (eqs. 4-5) and
so needs scans that share an orientation. Between sensor-frame scans the pipeline here

1. finds the heading change from the images' log-polar magnitude spectra (Fourier-Mellin,
   :mod:`estimators.rotation`), which does not depend on the unknown translation;
2. draws the later scan turned back by that angle and phase-correlates it with the earlier
   one's image (:func:`estimators.phase_correlation.phase_correlate`, subpixel) for the
   translation;
3. optionally polishes the pose with a few ICP iterations started from it -- point-to-curve
   (:class:`CurveReference`, :func:`refine_on_curves`) with :mod:`estimators.icp`'s
   Gauss-Newton step -- a correlative-then-refine pipeline as in Olson's and Cartographer's
   matchers: the correlation finds the basin, ICP its bottom. A motion prior from the
   estimator's own increments (:func:`prediction_information`), held about the car's centre
   rather than the sensor, holds what the scans leave open (corridors).

:class:`ScanMatcher` does one pair of scans (any two sensors); :class:`RotationPhaseCorrelation`
chains the matches of one Lidar's consecutive scans into car poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from estimators.base import Estimator, SensorSetup
from estimators.icp import gauss_newton_step, point_to_line_jacobian, robust_weights
from estimators.motion_prior import prediction_sigma
from estimators.phase_correlation import ImageSpectrum, image_spectrum, phase_correlate
from estimators.rotation import heading_change, log_polar_spectrum
from estimators.scan_image import (
    DEFAULT_SIZE,
    check_image_geometry,
    pixel_shift_to_metres,
    scan_to_image,
)
from estimators.scan_matching import DEFAULT_MIN_RANGE
from lidar_env.se2 import compose, inverse, transform_points, wrap_angle

FloatArray = NDArray[np.float64]

#: Lowest confidence a match reports, so that a poor match still counts a little in a fusion.
MIN_CONFIDENCE = 1e-3
#: Log-polar grids (angles over the half turn the magnitude spectrum needs, radii) of the
#: rotation search: half-degree bins when the correlation is the answer, 1-degree bins and
#: fewer radii when a refinement follows (enough to land well within its basin, at a quarter
#: of the cost).
POLAR_GRID = (360, 64)
POLAR_GRID_BEFORE_REFINEMENT = (180, 32)
#: Neighbouring returns further apart than this [m] are not one surface (a depth jump).
MAX_SURFACE_GAP = 0.3
#: Neighbours on each side fitted with a return's local quadratic: 5 points for 3 unknowns.
SURFACE_HALF_WINDOW = 2
#: Refinement settings [m]: pairs beyond ``MAX_PAIR_DISTANCE`` are ignored; the Cauchy loss
#: scale and the inlier distance are a few times a cheap Lidar's 1-3 cm range noise.
MAX_PAIR_DISTANCE = 0.5
LOSS_SCALE = 0.05
INLIER_DISTANCE = 0.1
#: Information of a motion prior relative to one return's: ``(sigma_r / sigma_p)^2`` with the
#: range noise ``sigma_r`` = 1 cm and a prior good to ``sigma_p`` = 5 cm and 0.05 rad (a car
#: changes its step by ``a dt^2`` = 5 cm at 5 m/s^2 and 10 Hz). Hundreds of returns outweigh
#: it wherever they constrain the pose.
PRIOR_SIGMA = np.array([0.05, 0.05, 0.05])
RANGE_NOISE = 0.01
PRIOR_INFORMATION = (RANGE_NOISE / PRIOR_SIGMA) ** 2
#: A constant-velocity prediction over a scan interval ``dt`` misses the car's position by
#: about ``PREDICTION_ACCELERATION dt^2`` [m] (an indoor robot's brisk 0.5 m/s^2: 5 mm at 10 Hz,
#: 2 cm at 5 Hz), never trusted to better than ``motion_prior.MIN_PREDICTION_SIGMA`` [m] (a
#: match's own precision) nor worse than ``PRIOR_SIGMA``; see :func:`prediction_information`.
PREDICTION_ACCELERATION = 0.5
#: A translation direction with less information than this share of the best direction's is
#: open: the spurious information of normals tilted by noise (a few hundredths of a radian
#: on 1 cm noise) is a share of about their tilt squared, well under 2 %.
DEGENERACY_RATIO = 0.02
#: A refinement has converged when its step is below 10 micrometres and 1 microradian, far
#: under the millimetre a 1 cm noisy scan supports.
STEP_TOLERANCE = (1e-5, 1e-6)
#: A refinement step that moves no point further than this [m] keeps the pairs: a point that
#: then changes its nearest return sits halfway between two returns of one surface, whose
#: curves agree there (the k-d tree search is most of an iteration's cost).
REPAIR_DISTANCE = 0.005
#: Two refinements whose inlier shares differ by less than this are equally good fits (a
#: featureless corridor fits anywhere along it); the one nearer the prior then wins.
QUALITY_TOLERANCE = 0.02


class CurveReference:
    """A scan as a chain of local quadratics, for point-to-curve refinement.

    Point-to-line ICP (Censi 2008) pairs a point with the chord through two reference points;
    on a curved surface (a 0.3 m cylinder seen at 3 m with 1-degree beams) the chord lies up
    to ``c^2 / 8R`` ~ 1 mm inside the surface, a bias that changes with the sampling from scan
    to scan. Here each return carries the quadratic ``v = c + b u + a u^2`` (``u`` along the
    local chord, ``v`` across it) fitted by least squares to itself and up to
    ``SURFACE_HALF_WINDOW`` neighbours on each side in beam order that lie on the same surface
    (a line with fewer than three points); a point's residual is its distance to that curve
    along the curve's normal. Fitting more points than parameters also averages the range
    noise: :attr:`smoothed` holds each return moved onto its own curve.

    Args:
        ranges: ``(n,)`` [m]; beam_angles: ``(n,)`` [rad] in beam order; max_range: [m].
    """

    def __init__(self, ranges: FloatArray, beam_angles: FloatArray, max_range: float) -> None:
        hit = np.flatnonzero((ranges < max_range) & (ranges > DEFAULT_MIN_RANGE))
        angles = beam_angles[hit]
        self.points = np.column_stack([ranges[hit] * np.cos(angles), ranges[hit] * np.sin(angles)])
        count = len(self.points)
        if count < 3:
            raise ValueError(f"reference scan: expected at least 3 returns, got {count}")
        self.tree = cKDTree(self.points)
        n_beams = len(ranges)
        # Neighbours at beam offsets -h..h on the same surface: every link of the chain joins
        # adjacent beams less than MAX_SURFACE_GAP apart.
        half = SURFACE_HALF_WINDOW
        offsets = np.arange(-half, half + 1)
        following = np.append(np.arange(1, count), 0)
        linked = ((hit[following] - hit) % n_beams == 1) & (
            np.hypot(*(self.points[following] - self.points).T) < MAX_SURFACE_GAP
        )
        if not _full_turn(beam_angles):
            linked[-1] = False  # the last beam does not neighbour the first
        rows = np.arange(count)
        # links[:, h + s] joins neighbours s and s + 1 (s = -h..h-1); neighbour o < 0 is on the
        # surface when every link from it up to the return holds, o > 0 likewise.
        links = linked[(rows[:, None] + np.arange(-half, half)) % count]
        valid = np.hstack(
            [
                np.cumprod(links[:, half - 1 :: -1], axis=1)[:, ::-1],
                np.ones((count, 1), dtype=bool),
                np.cumprod(links[:, half:], axis=1),
            ]
        ).astype(bool)
        neighbours = self.points[(rows[:, None] + offsets) % count]
        # Local frame: along the chord between the outermost neighbours on the same surface.
        first = np.argmax(valid, axis=1)
        last = len(offsets) - 1 - np.argmax(valid[:, ::-1], axis=1)
        chord = neighbours[rows, last] - neighbours[rows, first]
        length = np.hypot(*chord.T)
        self.pointlike = length < 1e-9
        self.tangents = chord / np.where(self.pointlike, 1.0, length)[:, None]
        self.normals = np.column_stack([-self.tangents[:, 1], self.tangents[:, 0]])
        local = neighbours - self.points[:, None, :]
        u = np.einsum("mkj,mj->mk", local, self.tangents)
        v = np.einsum("mkj,mj->mk", local, self.normals)
        # Weighted normal equations of v = c + b u + a u^2; the tiny ridge on a turns an
        # under-determined fit (two points) into the line through them.
        design = np.stack([np.ones_like(u), u, u**2], axis=-1) * valid[..., None]
        normal_matrix = np.einsum("mki,mkj->mij", design, design)
        scale = np.maximum(length, 1e-3) ** 4
        normal_matrix[:, 2, 2] += 1e-9 * scale
        normal_matrix[self.pointlike] = np.eye(3)
        coefficients = np.linalg.solve(
            normal_matrix, np.einsum("mki,mk->mi", design, v)[..., None]
        )[..., 0]
        coefficients[self.pointlike] = 0.0
        self.c, self.b, self.a = coefficients.T
        self.smoothed = self.points + self.c[:, None] * self.normals

    def correspond(self, points: FloatArray) -> tuple[NDArray[np.intp], FloatArray, FloatArray]:
        """For the points ``(M, 2)`` (reference frame) whose nearest return lies within
        ``MAX_PAIR_DISTANCE`` and on a surface: their index, the nearest point on that return's
        curve, and its unit normal.

        A lone return (no neighbour on the same surface: a thin post, or a wall seen so
        obliquely that its returns lie far apart) pairs with nothing: point-to-point pairs with
        the same beams of the other scan would pull the match towards no motion.
        """
        index, k = self.nearest_returns(points)
        return (index, *self.project(points, index, k))

    def nearest_returns(self, points: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The indices of the points ``(M, 2)`` that pair (see :meth:`correspond`) and of the
        returns they pair with."""
        distance, nearest = self.tree.query(points, distance_upper_bound=MAX_PAIR_DISTANCE)
        index = np.flatnonzero(np.isfinite(distance))
        index = index[~self.pointlike[nearest[index]]]
        return index, nearest[index]

    def project(
        self, points: FloatArray, index: NDArray[np.intp], k: NDArray[np.intp]
    ) -> tuple[FloatArray, FloatArray]:
        """The nearest points on the curves of returns ``k`` to ``points[index]``, and the
        curves' unit normals there."""
        offset = points[index] - self.points[k]
        tangent, normal = self.tangents[k], self.normals[k]
        u = np.einsum("ij,ij->i", offset, tangent)
        slope = 2.0 * self.a[k] * u + self.b[k]
        anchors = (
            self.points[k]
            + u[:, None] * tangent
            + (self.c[k] + self.b[k] * u + self.a[k] * u**2)[:, None] * normal
        )
        normals = (normal - slope[:, None] * tangent) / np.sqrt(1.0 + slope**2)[:, None]
        return anchors, normals


def refine_on_curves(
    reference: CurveReference,
    points: FloatArray,
    initial: FloatArray,
    iterations: int,
    prior: FloatArray | None = None,
    pivot: FloatArray | None = None,
    prior_information: FloatArray = PRIOR_INFORMATION,
) -> tuple[FloatArray, float]:
    """Point-to-curve ICP of ``points`` (M, 2, query sensor frame) onto ``reference`` from the
    pose ``initial`` (3,) for at most ``iterations`` (>= 1); returns the pose and the share of
    points within ``INLIER_DISTANCE`` of the reference surface (the match's confidence). The
    Gauss-Newton step and robust weights are :mod:`estimators.icp`'s.

    ``prior`` (3,): a predicted pose, added with ``prior_information`` (3,) (relative to one
    return's; by default the weak ``PRIOR_INFORMATION``).
    Where the scans leave a translation direction open (a featureless corridor) their
    information along it is not zero but noise (normals fitted to noisy walls tilt by a few
    hundredths of a radian), and that noise would outweigh any weak prior; so a direction
    whose information is below ``DEGENERACY_RATIO`` of the best direction's takes the prior's
    value outright (solution remapping, Zhang, Kaess & Singh, ICRA 2016).

    ``pivot`` (2,) [m, query sensor frame]: the point whose position the prior's translation
    predicts (default the sensor itself). A motion prediction is one of the car, whose heading
    is the least certain part of it: about the car's centre, a heading error of the prediction
    does not shift the predicted position, whereas at a sensor mounted ``l`` away it shifts it
    by ``l`` times the error -- which the open direction of a corridor would then take over.
    """
    pose = np.asarray(initial, dtype=np.float64).copy()
    pivot = np.zeros(2) if pivot is None else np.asarray(pivot, dtype=np.float64)
    quality = 0.0
    reach = float(np.max(np.hypot(points[:, 0], points[:, 1]), initial=0.0))
    pairs = None
    for _ in range(iterations):
        moved = transform_points(pose, points)
        if pairs is None:
            pairs = reference.nearest_returns(moved)
        index, k = pairs
        if len(index) < 3:
            break
        anchors, normals = reference.project(moved, index, k)
        residuals = np.einsum("ij,ij->i", moved[index] - anchors, normals)
        # Scored before the step, which by then is tiny: one correspondence search saved.
        quality = np.count_nonzero(np.abs(residuals) < INLIER_DISTANCE) / len(points)
        jacobian = point_to_line_jacobian(moved[index], pose[:2], normals)
        weights = robust_weights(residuals, "cauchy", LOSS_SCALE)
        if prior is None:
            step = gauss_newton_step(jacobian, residuals, weights)
        else:
            # The prior enters as three more residual rows, on the pivot's position and the
            # heading: r + J d = (pivot moved by pose + d) - (pivot moved by prior), linearised.
            lever = _rotate(pose[2], pivot)
            prior_jacobian = np.array([[1.0, 0.0, -lever[1]], [0.0, 1.0, lever[0]], [0, 0, 1]])
            prior_residuals = -pose_difference(
                np.append(prior[:2] + _rotate(prior[2], pivot), prior[2]),
                np.append(pose[:2] + lever, pose[2]),
            )
            step = gauss_newton_step(
                np.vstack([jacobian, prior_jacobian]),
                np.concatenate([residuals, prior_residuals]),
                np.concatenate([weights, prior_information]),
            )
            open_direction = _degenerate_translation(jacobian, weights)
            if open_direction is not None:
                predicted = prior[:2] + _rotate(prior[2], pivot)
                moved_pivot = pose[:2] + step[:2] + _rotate(pose[2] + step[2], pivot)
                step[:2] += open_direction * (open_direction @ (predicted - moved_pivot))
        pose = pose + step
        pose[2] = float(wrap_angle(pose[2]))
        if np.hypot(step[0], step[1]) < STEP_TOLERANCE[0] and abs(step[2]) < STEP_TOLERANCE[1]:
            break
        if np.hypot(step[0], step[1]) + abs(step[2]) * reach > REPAIR_DISTANCE:
            pairs = None  # points moved enough to have new nearest returns
    return pose, float(quality)


def _rotate(angle: float, vector: FloatArray) -> FloatArray:
    """``R(angle) v`` for one vector ``v`` (2,)."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([c * vector[0] - s * vector[1], s * vector[0] + c * vector[1]])


def _degenerate_translation(jacobian: FloatArray, weights: FloatArray) -> FloatArray | None:
    """The unit translation direction (2,) the weighted pairs do not constrain, or None.

    The information on translation with the heading marginalised out is the Schur complement
    of the 3x3 normal matrix; its weaker eigen-direction is open when its eigenvalue is under
    ``DEGENERACY_RATIO`` times the stronger one.
    """
    information = (jacobian * weights[:, None]).T @ jacobian
    if information[2, 2] <= 0:
        return None
    translation = (
        information[:2, :2] - np.outer(information[:2, 2], information[2, :2]) / (information[2, 2])
    )
    values, vectors = np.linalg.eigh(translation)
    if values[1] <= 0 or values[0] >= DEGENERACY_RATIO * values[1]:
        return None
    return vectors[:, 0]


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
        return scan_to_image(
            self.ranges, self.beam_angles + turn, self.max_range, self.image_size, self.resolution
        )

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
    def spectrum(self) -> ImageSpectrum:
        """The image's whitened FFT (:func:`image_spectrum`)."""
        return image_spectrum(self.upright_image)


@dataclass(frozen=True)
class ScanMatch:
    """``pose`` (3,): the later sensor's pose (x [m], y [m], heading [rad]) in the earlier
    sensor's frame; ``confidence`` in [MIN_CONFIDENCE, 1]."""

    pose: FloatArray
    confidence: float


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
            raise ValueError(
                f"icp_iterations: expected an integer >= 0, got {self.icp_iterations!r}"
            )

    def prepare(self, ranges: ArrayLike, beam_angles: ArrayLike) -> PreparedScan:
        """Precompute a scan ``(n,)`` [m] with beam directions ``(n,)`` [rad] for matching."""
        ranges = np.asarray(ranges, dtype=np.float64)
        angles = np.asarray(beam_angles, dtype=np.float64)
        hit = (ranges < self.max_range) & (ranges > DEFAULT_MIN_RANGE)
        reference = None
        points = np.column_stack(
            [ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])]
        )
        if self.icp_iterations and len(points) >= 3:
            reference = CurveReference(ranges, angles, self.max_range)
            points = reference.smoothed
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
        profiles = None
        if prior is None and _full_turn(earlier.beam_angles, later.beam_angles):
            profiles = (earlier.ranges, later.ranges, earlier.beam_angles, self.max_range)
        hint = None if prior is None else float(np.asarray(prior, dtype=np.float64)[2])
        rotation = heading_change(earlier.polar, later.polar, hint, profiles)
        turned = image_spectrum(later.image(rotation.angle))
        correlation = phase_correlate(earlier.spectrum, turned)
        # The turned later image sees the scene shifted by minus the sensor's translation.
        translation = -pixel_shift_to_metres(correlation.shift, self._resolution)
        pose = np.array([translation[0], translation[1], rotation.angle])
        # Peak-to-runner-up ratio r >= 1 maps to 1 - 1/r: 0 when ambiguous, -> 1 when unique.
        confidence = rotation.confidence * (1.0 - 1.0 / max(correlation.confidence, 1.0))
        return ScanMatch(pose, float(np.clip(confidence, MIN_CONFIDENCE, 1.0)))

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
        if earlier.reference is None:
            raise ValueError("refine: expected a matcher with icp_iterations > 0, got 0")
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
        if prior is not None:
            candidates.sort(
                key=lambda r: float(np.sum((pose_difference(r[0], prior) / PRIOR_SIGMA) ** 2))
            )
        pose, confidence = candidates[0]
        return ScanMatch(pose, float(np.clip(confidence, MIN_CONFIDENCE, 1.0)))


def prediction_information(dt: float, speed: float = 0.0, jitter: float = 0.0) -> FloatArray:
    """Information (3,) of a constant-velocity prediction over ``dt`` [s], relative to one
    return's (as ``PRIOR_INFORMATION``): its position good to ``PREDICTION_ACCELERATION dt^2``
    plus ``speed`` [m/s] times the clock's ``jitter`` [s] (a scan stamped early or late has
    moved further or less than its interval says), clipped to
    [``motion_prior.MIN_PREDICTION_SIGMA``, ``PRIOR_SIGMA``]; its heading to ``PRIOR_SIGMA``.

    Where the returns pin the pose down, hundreds of them outweigh it; where they leave a
    direction nearly open (the exit of a corridor, a hall with a few posts in range), it
    keeps the step from following the noise of a handful of returns.
    """
    if not dt > 0:
        raise ValueError(f"dt: expected a positive scan interval [s], got {dt}")
    if not (speed >= 0 and jitter >= 0):
        raise ValueError(f"speed and jitter: expected values >= 0, got {speed}, {jitter}")
    sigma = prediction_sigma(dt, speed, jitter, PREDICTION_ACCELERATION, PRIOR_SIGMA[0])
    return (RANGE_NOISE / np.array([sigma, sigma, PRIOR_SIGMA[2]])) ** 2


def refinement_starts(start: FloatArray, prior: FloatArray | None) -> list[FloatArray]:
    """Where to start refinements: ``start``, and also ``prior`` where the two disagree by more
    than ``PRIOR_SIGMA`` (a correlation fooled by a repetitive scene)."""
    if prior is not None and np.any(np.abs(pose_difference(start, prior)) > PRIOR_SIGMA):
        return [start, prior]
    return [start]


def pose_difference(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a - b`` with the heading difference wrapped."""
    difference = np.asarray(a, dtype=np.float64) - b
    difference[2] = float(wrap_angle(difference[2]))
    return difference


def motion_from_sensor_match(mount: ArrayLike, sensor_motion: ArrayLike) -> FloatArray:
    """Car motion ``Δ = mount ⊕ z ⊕ mount⁻¹`` from one sensor's own match ``z`` (same sensor
    at both times)."""
    return compose(compose(mount, sensor_motion), inverse(mount))


def _full_turn(*angle_sets: FloatArray) -> bool:
    """Beams evenly spread over a full turn in every set (range profiles then correlate)."""
    for angles in angle_sets:
        steps = np.diff(angles)
        if not np.allclose(steps, 2.0 * np.pi / len(angles), atol=1e-6):
            return False
    return True


def require_sensor_frame(setup: SensorSetup, estimator: str) -> None:
    """Raise unless the scans are in their sensors' own frames, which these estimators need:
    they estimate the heading change from the scans' rotation, and each sensor's pose is the
    car's pose composed with its mount."""
    if setup.world_aligned:
        raise ValueError(
            f"{estimator}: expected sensor-frame scans (scan_frame='sensor'), got world-aligned "
            "scans; the paper's estimators (pc, pc_pg) take those"
        )


def constant_velocity(last_motion: FloatArray, last_dt: float, dt: float) -> FloatArray:
    """The motion (3,) over ``dt`` [s] at the velocity of ``last_motion`` over ``last_dt`` [s]
    (a prediction from the estimator's own increments, never from odometry)."""
    return np.asarray(last_motion, dtype=np.float64) * (dt / last_dt if last_dt > 0 else 1.0)


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
    _last_dt: float = field(default=0.0, init=False, repr=False)

    def _reset_state(self) -> None:
        setup = self._checked_setup()
        require_sensor_frame(setup, type(self).__name__)
        self._matcher = ScanMatcher(
            setup.max_range, self.image_size, self.resolution, self.icp_iterations
        )
        self._previous = None
        self._last_motion = None
        self._last_dt = 0.0

    def _checked_setup(self) -> SensorSetup:
        assert self.setup is not None
        if isinstance(self.lidar, bool) or self.lidar not in range(self.setup.n_lidars):
            raise ValueError(
                f"lidar: expected an index in 0..{self.setup.n_lidars - 1} "
                f"({', '.join(self.setup.keys)}), got {self.lidar!r}"
            )
        return self.setup

    def _start(self, scans: dict[str, FloatArray], t: float) -> None:
        assert self._matcher is not None and self.setup is not None
        self._previous = self._matcher.prepare(
            scans[self.setup.keys[self.lidar]], self.setup.beam_angles
        )

    def _step(self, scans: dict[str, FloatArray], t: float) -> FloatArray:
        assert self._matcher is not None and self._previous is not None and self.setup is not None
        current = self._matcher.prepare(scans[self.setup.keys[self.lidar]], self.setup.beam_angles)
        dt = t - self._times[-1]
        prior = None
        if self._last_motion is not None:
            prior = constant_velocity(self._last_motion, self._last_dt, dt)
        match = self._matcher.match(self._previous, current, prior)
        self._previous = current
        self._last_motion, self._last_dt = match.pose, dt
        mount = self.setup.mounts[self.lidar]
        return compose(self.pose, motion_from_sensor_match(mount, match.pose))
