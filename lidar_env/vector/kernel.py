"""The compiled step of N ``DualLidar-v0`` cars: motion, collision, progress, reward, episode
end and every Lidar's noisy scan, for all stepped envs in one numba call.

Every per-env quantity is a row of an ``(N, ...)`` array; each env's scene (obstacles, their
grid, its trace, its random generator's state) is an item of a numba typed list (:mod:`.slots`).
:func:`step_batch` is one env step (the action check, then :func:`step_envs`) in one call. The math
is the single env's own compiled functions, called in its order:
:func:`lidar_env.vehicle.car.drive_arc` for the motion and collision,
:func:`lidar_env.routes.trace_geometry.project_onto_polyline` for the progress,
:func:`lidar_env.vehicle.car.mount_poses` and
:func:`lidar_env.sensors.layout_kernels.cast_packed` and
:func:`~lidar_env.sensors.layout_kernels.readings` for the scans; with moving obstacles,
:func:`lidar_env.movers.kernels.advance_crowd` for the crowd (its waypoint draws first),
:func:`lidar_env.movers.crowd.fill_car_circles` for the car as yielding movers see it and
:func:`lidar_env.vehicle.car.drive_arc_among_movers` for the car among them. Each env draws its
noise (and its movers' waypoints) from its own ``numpy.random.Generator`` inside the kernel
(:mod:`lidar_env.vector.draws`: numpy's draws bit for bit, advancing the generator's own state), so
an env's stream is the one a single env seeded alike would use.

Units: metres, radians, seconds; poses are ``(x, y, heading)`` in the world frame.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from lidar_env.movers.crowd import WAYPOINT_TRIES, fill_car_circles
from lidar_env.movers.kernels import advance_crowd
from lidar_env.routes.trace_geometry import project_onto_polyline
from lidar_env.sensors.layout_kernels import cast_packed, readings
from lidar_env.sensors.ray_casting import scan_loop
from lidar_env.vector.draws import (
    fill_standard_normal_pair,
    fill_standard_normals,
    fill_uniforms,
    words_at,
)
from lidar_env.vector.unowned import unowned, unowned_scene
from lidar_env.vehicle.car import arc_pose, drive_arc, drive_arc_among_movers, mount_poses
from lidar_env.world.primitive_grid import cell_block, segment_distance2

#: [m] added to the reach of a move when picking the obstacles it may touch: far above the
#: rounding of the arc's closed form (~1e-7 m on the flattest arcs, yaw rates near 1e-9 rad/s),
#: far below any obstacle spacing, so the pick stays conservative and culls nearly all.
REACH_MARGIN = 0.01
#: The beam wedge of :func:`lidar_env.world.primitive_grid.cell_block` for a whole disc
#: (width 2 pi).
WHOLE_DISC = (2.0 * math.pi, 1.0, 0.0, 1.0, 0.0)


@njit(cache=True)
@scan_loop  # the scan's kernels compiled inline: no calls, no reference counts per env
def observe_envs(
    envs: NDArray[np.int64],
    pose: NDArray[np.float64],
    sensor_poses: NDArray[np.float64],
    scans: NDArray[np.float32],
    scene: tuple,
    sensors: tuple,
    work: tuple,
    crowd: tuple,
) -> None:
    """Scan from the cars of ``envs`` at ``pose`` (N, 3) into ``scans`` (N, total beams).

    ``sensor_poses`` (N, K, 3) receives the Lidars' world poses. ``scene`` is
    :attr:`lidar_env.vector.slots.SceneSlots.scene` (each env's generator state taken by its
    address, its last; its world's arrays are taken only where its world differs from the env
    before);
    ``sensors`` ``(mounts (K, 3), world_aligned, noisy, dropping, beams, params)``
    with ``beams`` and ``params`` as :func:`~lidar_env.sensors.layout_kernels.cast_packed` takes
    them; ``work`` the scratch of :meth:`lidar_env.vector.env.DualLidarVectorEnv._work` (nothing is
    allocated per env); ``crowd`` :attr:`lidar_env.vector.crowds.CrowdSlots.kernel`, whose
    movers the Lidars see (none when M = 0). Draws per env: a standard normal per beam if any
    Lidar is noisy, then a uniform per beam if any drops out (the order of
    :meth:`lidar_env.sensors.lidar_layout.LidarLayout.scan`), as numpy's array draws; the envs
    at places 2 m and 2 m + 1 of ``envs`` draw together, each from its own generator.
    """
    # every array used per env is an unowned view (of the arguments, held by the caller)
    items, first_edge, world_key, addresses = scene[0], unowned(scene[1]), unowned(scene[4]), \
        unowned(scene[6])
    pose, sensor_poses, scans = unowned(pose), unowned(sensor_poses), unowned(scans)
    mounts, world_aligned, noisy, dropping = unowned(sensors[0]), sensors[1], sensors[2], \
        sensors[3]
    beams, params = (unowned(sensors[4][0]), unowned(sensors[4][1])), unowned(sensors[5])
    cast_from, draws, circle_seen, segment_seen, stamp = unowned(work[0]), unowned(work[1]), \
        unowned(work[2]), unowned(work[3]), unowned(work[4])
    total, k = scans.shape[1], mounts.shape[0]
    # the draws of an env at an even place of envs, then of the env after it
    gaussians = draws[:total] if noisy else draws[:0]
    next_gaussians = draws[total:2 * total] if noisy else draws[:0]
    uniforms = draws[2 * total:3 * total] if dropping else draws[:0]
    next_uniforms = draws[3 * total:4 * total] if dropping else draws[:0]
    no_car, no_facing = np.empty(0), np.empty(0, dtype=np.int64)
    positions, radius, movers = unowned(crowd[0]), crowd[7][0], unowned(crowd[8][0])
    if envs.shape[0] == 0:
        return
    last = envs[0]  # the env whose world arrays are viewed (the typed list holds them)
    circles, segments, grid, _, _ = unowned_scene(items[last])
    count = envs.shape[0]
    for q in range(count):
        i = envs[q]
        if world_key[i] != world_key[last]:
            last = i
            circles, segments, grid, _, _ = unowned_scene(items[i])
        if q % 2 == 0:  # this env's draws and the next one's, two generators interleaved
            words = words_at(addresses[i])
            if q + 1 < count:
                other = words_at(addresses[envs[q + 1]])
                fill_standard_normal_pair(words, gaussians, other, next_gaussians)
                fill_uniforms(other, next_uniforms)
            else:
                fill_standard_normals(words, gaussians)
            fill_uniforms(words, uniforms)
        mount_poses(pose[i], mounts, sensor_poses[i])
        cast_from[:] = sensor_poses[i]
        if world_aligned:
            cast_from[:, 2] = 0.0  # beam i along world angle beam_angles[i]
        for j in range(movers.shape[0]):  # Crowd.circles
            movers[j, 0], movers[j, 1], movers[j, 2] = positions[i, j, 0], positions[i, j, 1], \
                radius
        exact = cast_packed(circles, segments, first_edge[i], grid, cast_from,
                            beams, params, movers, no_car, (circle_seen, segment_seen),
                            stamp[0], no_facing)
        stamp[0] += k
        if q % 2 == 0:
            readings(exact, params, gaussians, uniforms, scans[i])
        else:
            readings(exact, params, next_gaussians, next_uniforms, scans[i])


@njit(cache=True)
def obstacles_within(
    x: float, y: float, reach: float, circles: NDArray[np.float64], segments: NDArray[np.float64],
    grid: tuple, seen: tuple, stamp: NDArray[np.int64], near_circles: NDArray[np.float64],
    near_segments: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The circles (n, 3) and segments (m, 4) that come within ``reach`` [m] of (x, y), as
    views of the first rows of ``near_circles`` and ``near_segments`` (at least as long as
    ``circles`` and ``segments``), which they overwrite.

    Every pose of one control step keeps the car's centre within ``|speed| dt`` of its start
    (a chord is never longer than its arc) and the box within its half-diagonal of the centre,
    so with ``reach`` = the two plus a margin, the obstacles left out cannot touch it: the
    collision check over the rest gives the same answer as over all (the culling is the
    broad phase the single car does not need). Only the cells of the world's ``grid``
    (:class:`~lidar_env.world.primitive_grid.PrimitiveGrid`) under the square of half side ``reach``
    are visited (a circle is listed in every cell its bounding box touches, a segment in every
    cell it passes through); ``seen`` ``(circle_seen, segment_seen)`` and the stamp
    ``stamp[0]`` (then advanced) make a primitive listed in several of them count once, as
    :func:`lidar_env.sensors.ray_casting.cast_sensor` uses them. The near ones come in cell order,
    not index order: the check only asks whether any touches.
    """
    circle_seen, segment_seen = seen
    mark = stamp[0]
    stamp[0] += 1
    nx, circle_start, circle_ids, segment_start, segment_ids = grid[3], grid[5], grid[6], \
        grid[7], grid[8]
    c0, c1, r0, r1, _, _ = cell_block(x, y, reach, WHOLE_DISC, grid[:5])
    n_circles = n_segments = 0
    for iy in range(r0, r1 + 1):
        for c in range(iy * nx + c0, iy * nx + c1 + 1):
            for p in range(circle_start[c], circle_start[c + 1]):
                j = circle_ids[p]
                if circle_seen[j] == mark:
                    continue
                circle_seen[j] = mark
                dx, dy, r = circles[j, 0] - x, circles[j, 1] - y, circles[j, 2] + reach
                if dx * dx + dy * dy <= r * r:
                    for k in range(3):
                        near_circles[n_circles, k] = circles[j, k]
                    n_circles += 1
            for p in range(segment_start[c], segment_start[c + 1]):
                j = segment_ids[p]
                if segment_seen[j] == mark:
                    continue
                segment_seen[j] = mark
                if segment_distance2(x, y, segments[j]) <= reach * reach:
                    for k in range(4):
                        near_segments[n_segments, k] = segments[j, k]
                    n_segments += 1
    return near_circles[:n_circles], near_segments[:n_segments]


@njit(cache=True)
def drive_clear_arc(pose: NDArray[np.float64], speed: float, yaw_rate: float, duration: float,
                    substeps: int) -> bool:
    """:func:`lidar_env.vehicle.car.drive_arc` with no obstacle within reach: ``pose`` moved
    to its last substep's pose (``substeps`` >= 1), the same floats (no substep can touch, so
    only the last one's pose is computed, its heading wrapped as ``drive_arc`` wraps it);
    returns False (no hit)."""
    x0, y0, h0 = pose[0], pose[1], pose[2]
    x, y, h, _, _ = arc_pose(x0, y0, h0, math.cos(h0), math.sin(h0), speed, yaw_rate,
                             duration * substeps / substeps)
    pose[0], pose[1], pose[2] = x, y, (h + math.pi) % (2.0 * math.pi) - math.pi
    return False


@njit(cache=True)
def step_envs(
    envs: NDArray[np.int64],
    speed: NDArray[np.float64],
    yaw_rate: NDArray[np.float64],
    checks: NDArray[np.int64],
    state: tuple,
    outcome: tuple,
    scene: tuple,
    sensors: tuple,
    work: tuple,
    constants: NDArray[np.float64],
    crowd: tuple,
) -> int:
    """One control step of the cars of ``envs`` (the single env's ``step`` after its action
    check), in place; returns how many of them terminated or truncated.

    ``speed`` [m/s], ``yaw_rate`` [rad/s] and ``checks`` (collision checks) are (N,) per env.
    ``state`` is ``(pose (N, 3), sensor_poses (N, K, 3), time (N,), arc (N,), progress (N,),
    cross_track (N,), collision (N,), scans (N, total))``; ``outcome`` ``(reward, terminated,
    truncated)`` (N,) each; ``scene``, ``sensors``, ``work`` and ``crowd`` as
    :func:`observe_envs` takes them (each env's crowd steps first, as in the single env).
    ``constants``: control_dt [s], car half length and half width [m], cross_track_penalty
    [1/s], collision_penalty, goal_tolerance [m], the truncation time [s]
    (``max_episode_time - 1e-9``), the progress window [m].
    """
    pose, sensor_poses, time, arc, progress, cross_track, collision, scans = state
    reward, terminated, truncated = outcome
    items, closed, length, world_key, trace_key = scene[0], scene[2], scene[3], scene[4], \
        scene[5]
    dt, half_length, half_width = constants[0], constants[1], constants[2]
    cross_penalty, collision_penalty, goal_tolerance = constants[3], constants[4], constants[5]
    time_limit, window = constants[6], constants[7]
    half_diagonal = math.hypot(half_length, half_width)
    ended = 0
    if envs.shape[0] == 0:
        return ended
    # the arrays used per env as unowned views (see observe_envs), the crowd's step aside
    car_pose, seen = unowned(pose), (unowned(work[2]), unowned(work[3]))
    stamp, near = unowned(work[4]), (unowned(work[5]), unowned(work[6]))
    held = envs[0]  # the env whose world and trace arrays are viewed (the typed list holds them)
    item = items[held]
    circles, segments, grid, waypoints, trace_arc = unowned_scene(item)
    for i in envs:
        if world_key[i] != world_key[held] or trace_key[i] != trace_key[held]:
            held = i
            item = items[i]
            circles, segments, grid, waypoints, trace_arc = unowned_scene(item)
        reach = abs(speed[i]) * dt + half_diagonal + REACH_MARGIN
        near_circles, near_segments = obstacles_within(
            car_pose[i, 0], car_pose[i, 1], reach, circles, segments, grid, seen, stamp, near[0],
            near[1])
        if crowd[0].shape[1] == 0 and near_circles.shape[0] + near_segments.shape[0] == 0:
            hit = drive_clear_arc(car_pose[i], speed[i], yaw_rate[i], dt, checks[i])
        elif crowd[0].shape[1] == 0:
            hit = drive_arc(car_pose[i], speed[i], yaw_rate[i], dt, checks[i], half_length,
                            half_width, near_circles, near_segments)
        else:  # movers first (their waypoint draws), then the car among them
            start = step_crowd(i, car_pose[i], half_length, half_width, dt, crowd,
                               words_at(scene[6][i]), item[0], item[1], item[2])
            hit = drive_arc_among_movers(car_pose[i], speed[i], yaw_rate[i], dt, checks[i],
                                         half_length, half_width, near_circles, near_segments,
                                         start, crowd[1][i])
        time[i] += dt
        previous = arc[i]
        position, error = project_onto_polyline(waypoints, trace_arc, car_pose[i, 0],
                                                car_pose[i, 1], previous, window, closed[i])
        arc[i] = position
        progress[i] = position / length[i]
        cross_track[i] = error
        collision[i] = hit
        r = position - previous - cross_penalty * abs(error) * dt
        if hit:
            r -= collision_penalty
        reward[i] = r
        done = hit or position >= length[i] - goal_tolerance
        terminated[i] = done
        truncated[i] = not done and time[i] >= time_limit
        if done or truncated[i]:
            ended += 1
    observe_envs(envs, pose, sensor_poses, scans, scene, sensors, work, crowd)
    return ended


@njit(cache=True)
def step_crowd(
    i: int, car_pose: NDArray[np.float64], half_length: float, half_width: float, dt: float,
    crowd: tuple, words: NDArray[np.uint64], circles: NDArray[np.float64],
    segments: NDArray[np.float64], grid: Any,
) -> NDArray[np.float64]:
    """Env ``i``'s crowd (``crowd`` as :func:`step_envs` takes it) advanced by ``dt`` [s], as
    :meth:`lidar_env.movers.crowd.Crowd.step` does (its waypoints drawn from the generator state
    ``words``), among the world's ``circles``, ``segments`` and ``grid`` and (yielding movers)
    the car standing at ``car_pose``. Returns the movers' circles (M, 3) [m] before the step (a
    view of the crowd's scratch)."""
    positions, velocities, waypoints, speeds, stuck, needs, bounds, params, work = crowd
    start, car, draws = work
    radius = params[0]
    for j in range(start.shape[0]):  # Crowd.circles, taken before the step
        start[j, 0], start[j, 1], start[j, 2] = positions[i, j, 0], positions[i, j, 1], radius
    if car.shape[0] > 0:  # car_circles of the standing car
        fill_car_circles(car_pose[0], car_pose[1], car_pose[2], half_length, half_width,
                         params[1], 0.0, 0.0, car)
    waiting = 0
    for j in range(needs.shape[1]):
        waiting += needs[i, j]
    chosen = draws[:waiting * WAYPOINT_TRIES * 2]
    fill_uniforms(words, chosen)  # rng.random((waiting, WAYPOINT_TRIES, 2))
    advance_crowd(positions[i], velocities[i], waypoints[i], speeds[i], stuck[i], needs[i],
                  chosen.reshape((waiting, WAYPOINT_TRIES, 2)), radius, dt, bounds[i], circles,
                  segments, grid, car)
    return start


@njit(cache=True)
def plan_motion(
    actions: NDArray[np.float64],
    envs: NDArray[np.int64],
    limits: NDArray[np.float64],
    substeps: int,
    max_checks: int,
    other_speed: NDArray[np.float64],
    speed: NDArray[np.float64],
    yaw_rate: NDArray[np.float64],
    checks: NDArray[np.int64],
) -> int:
    """Speed [m/s], yaw rate [rad/s] and collision checks of the sub-envs ``envs`` from their
    ``actions`` (N, 2), as the single env's ``step`` and
    :meth:`lidar_env.vehicle.car.Car.substeps_for` compute them (the same float operations, in
    their order), into ``speed``, ``yaw_rate``, ``checks``.

    ``limits`` holds max_speed [m/s], max_yaw_rate [rad/s], control_dt [s], the car's
    half-diagonal [m] and its largest move between two checks [m]; ``other_speed`` (N,) each
    env's fastest mover [m/s] (0 without movers), as ``Car.substeps_for`` adds it. Returns -1,
    or ``-2 - i`` for the first sub-env ``i`` whose action is not finite, or the first ``i``
    whose move needs more than ``max_checks`` checks (nothing is meant to move then).
    """
    max_speed, max_yaw_rate, duration, half_diagonal, max_step = limits
    for i in envs:
        throttle, steer = actions[i, 0], actions[i, 1]
        if not (math.isfinite(throttle) and math.isfinite(steer)):
            return -2 - i
        v = min(max(throttle, -1.0), 1.0) * max_speed
        w = min(max(steer, -1.0), 1.0) * max_yaw_rate
        corner_travel = (abs(v) + abs(w) * half_diagonal) * duration  # [m]
        if other_speed[i] > 0.0:  # relative to the fastest mover
            corner_travel += other_speed[i] * duration
        needed = math.ceil(corner_travel / max_step)
        if needed > max_checks:
            return i
        speed[i], yaw_rate[i], checks[i] = v, w, max(substeps, needed, 1)
    return -1


@njit(cache=True)
def step_batch(
    actions: NDArray[np.float64],
    envs: NDArray[np.int64],
    limits: NDArray[np.float64],
    substeps: int,
    max_checks: int,
    other_speed: NDArray[np.float64],
    motion: tuple,
    state: tuple,
    outcome: tuple,
    scene: tuple,
    sensors: tuple,
    work: tuple,
    constants: NDArray[np.float64],
    crowd: tuple,
) -> tuple[int, int]:
    """:func:`plan_motion` and, if every action of ``envs`` is good, :func:`step_envs`: one
    env step in one call (numba unboxes the arguments, ~0.1 to 0.7 us each, once).

    ``motion`` is ``(speed, yaw_rate, checks)`` (N,) each, which :func:`plan_motion` fills;
    the other arguments as those two take them. Returns ``(code, ended)``: ``plan_motion``'s
    code (-1 when the envs stepped; otherwise nothing moved) and how many envs terminated or
    truncated.
    """
    speed, yaw_rate, checks = motion
    code = plan_motion(actions, envs, limits, substeps, max_checks, other_speed, speed, yaw_rate,
                       checks)
    if code != -1:
        return code, 0
    return code, step_envs(envs, speed, yaw_rate, checks, state, outcome, scene, sensors, work,
                           constants, crowd)
