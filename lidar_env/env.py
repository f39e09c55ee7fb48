"""``DualLidar-v0``: a car with planar Lidars (two by default) driving along a trace through a
2-D world."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from lidar_env.config import EnvConfig
from lidar_env.core.errors import ArgumentTypeError, ConfigError, ResetNeededError
from lidar_env.core.kernel_cache import announce_first_compile
from lidar_env.env_views import EnvViews
from lidar_env.movers.crowd import Crowd, car_circles
from lidar_env.routes.trace_geometry import Trace, project_onto_polyline
from lidar_env.routes.traces import check_trace_name
from lidar_env.routes.user_traces import check_waypoints
from lidar_env.scenes import SceneCache, check_reset_options
from lidar_env.sensors.lidar_layout import LidarLayout, scan_packed_kernel
from lidar_env.vehicle.actions import checked_action
from lidar_env.vehicle.car import Car, mount_poses
from lidar_env.world.user_worlds import resolve_world
from lidar_env.world.world import World

#: [m] half-width of the arc window searched when tracking progress along the trace: far more
#: than the car moves per step (0.15 m at default settings), far less than the spacing between
#: zigzag legs, so progress never jumps to a neighbouring leg.
PROGRESS_WINDOW = 2.0


class DualLidarEnv(EnvViews, gym.Env[dict[str, NDArray[np.float32]], NDArray[np.float32]]):
    """A car with planar Lidars (two by default) drives along a trace through a 2-D world.

    ## Description

    The setting of the paper "Obstacles Detection and Motion Estimation by Using Multiple Lidar
    Sensors Data" (sections III.A-B, IV): a box-shaped car (0.8 m x 0.5 m) moves as a unicycle
    through a world of static obstacles (cylinders, walls, polygons; a pymunk ``Space``). By
    default two Lidars sit on the car at a fixed offset ("the main and the offset sensor";
    0.25 m ahead of and 0.25 m behind the car's centre on its axis); ``config["lidars"]``
    sets 1 to 8 of any mount, field of view, beam count and range. Each control step every
    Lidar takes one exact scan (by default 360 beams). The task is to follow a *trace* (a
    waypoint path from a start pose: ``straight``, ``right_turn`` or ``zigzag``, the paper's
    "strict, right-turn, zigzag" seeds; or, to test loop closure, ``loop``, a closed circuit
    driven once round, and ``out_and_back``, which turns around and comes back beside its
    outward lane; or the user's own waypoints) to its end; the ground-truth poses in ``info``
    are what Lidar-only motion estimators are scored against. With
    ``config["moving_obstacles"]`` M > 0, M pedestrians (circles of ``mover_radius``) walk
    between random free waypoints at their own speeds (:mod:`lidar_env.movers`): the Lidars
    see them exactly and touching one ends the episode like a wall. They keep clear of where the
    car stands (``config["mover_model"]`` "yielding"), but do not guess where it goes;
    "waypoints" pedestrians ignore the car altogether.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``; finite values outside [-1, 1] are clipped.

    | Index | Action            | Min                  | Max                 | Unit  |
    |-------|-------------------|----------------------|---------------------|-------|
    | 0     | linear velocity   | -max_speed (reverse) | +max_speed (1.5)    | m/s   |
    | 1     | yaw rate, CCW > 0 | -max_yaw_rate        | +max_yaw_rate (1.5) | rad/s |

    Both are held constant for ``control_dt`` (0.1 s): the car runs along a circular arc.

    ## Observation Space

    ``Dict`` of one ``Box(0, max_range_k, (n_beams_k,), float32)`` scan per Lidar of
    ``config["lidars"]`` (1 to 8; default two 360-beam, 360-degree, 10 m Lidars):

    | Key       | Sensor          | Length    | Beam 0 points at (*)            | Angles | Unit |
    |-----------|-----------------|-----------|---------------------------------|--------|------|
    | "lidar_1" | ``lidars[0]``   | n_beams_1 | forward (fov = 2 pi), else at   | CCW    | m    |
    |           | (main)          |           | -fov / 2 from forward           |        |      |
    | "lidar_2" | ``lidars[1]``   | n_beams_2 | as above                        | CCW    | m    |
    | ...       | up to "lidar_8" |           |                                 |        |      |

    Beams spread evenly over the Lidar's ``fov``, centred on its forward axis: a full turn has
    beam i at 2 pi i / n; a narrower Lidar has beam i at -fov / 2 + fov i / (n - 1), so a
    270-degree Lidar's beam 0 points at -135 degrees and its last beam at +135 degrees. Each
    value is the range [m] from that sensor's centre to the first obstacle along the beam, in
    [0, max_range]. A beam that hits nothing within ``max_range`` (or drops out, probability
    the Lidar's ``dropout_prob``, 0 by default, or reads below its ``min_range``, 0 by default:
    an invalid reading) reads exactly ``max_range``. Hits carry
    Gaussian noise of std the Lidar's ``range_noise_std`` (0.01 m by default;
    :func:`lidar_env.lidars_with_noise` sets both on every Lidar), clipped to [0, max_range).
    (*) With ``scan_frame="world"`` the beam angles are measured from world +x instead (the
    paper's simplification, as if the heading were known); the ranges are then cast exactly
    along those world directions, not interpolated from a sensor-frame scan.

    ## Rewards

    Per step: metres of arc gained along the trace, minus ``cross_track_penalty`` (0.1 /s)
    x |cross-track error [m]| x ``control_dt``, minus ``collision_penalty`` (10) on the step
    the car touches an obstacle.

    ## Starting State

    The car stands at the trace's start pose: each built-in world has a default start per trace
    seed; a user world starts at its free point of largest clearance near the map's centre
    (:mod:`lidar_env.world.user_worlds`). ``reset(options={"start": (x, y, heading)})`` overrides it
    (the trace is then fitted to the world from there). A start where the car's box touches or
    lies inside an obstacle, or outside the map, raises :class:`~lidar_env.scenes.StartPoseError`.
    Movers (if any) are placed at random free points from which they can walk straight to the
    trace, at least ``mover_clearance`` (1 m) from the car's box; a world too crowded for all of
    them raises a ``ConfigError`` saying how many fit.

    ## Episode End

    Termination: 1. the car is within ``goal_tolerance`` (0.3 m) of arc from the trace's end
    (on a ``loop``: it has driven the whole lap but ``goal_tolerance``, counted along the lap,
    so standing at the start does not count);
    2. the car's box touches an obstacle or a mover (it is stopped at the last free physics
    substep; movers move during the substeps too, in a straight line at the velocity they hold
    over the step).
    Truncation: 3. the episode time reaches ``max_episode_time`` (120 s).
    After either, ``step()`` raises :class:`~lidar_env.core.errors.ResetNeededError` until
    ``reset()`` (Gymnasium leaves stepping on undefined; the car must not drive on unnoticed).

    ## Info

    | Key                 | Meaning                                                 | Unit      |
    |---------------------|---------------------------------------------------------|-----------|
    | "pose"              | true car pose (x, y, heading), float64 (3,), world     | m, m, rad |
    | "lidar_poses"       | true world poses of lidar_1 .. lidar_K, float64 (K, 3) | m, m, rad |
    | "time"              | time since reset                                        | s         |
    | "progress"          | arc position / trace length, in [0, 1] (*)              | -         |
    | "arc_position"      | arc length of the car's projection onto the trace (*)   | m         |
    | "cross_track_error" | signed distance from the trace, positive = left of it   | m         |
    | "collision"         | the car touched an obstacle (or a mover) this step      | -         |
    | "moving_obstacles"  | movers' x, y, vx, vy, radius, float64 (M, 5), world;   | m, m/s, m |
    |                     | (0, 5) without movers; velocity held over the last step |           |

    Progress is tracked locally (within 2 m of arc of the previous step's), so it cannot jump
    to a neighbouring leg of a zigzag. (*) On a closed trace (``loop``) it is the distance
    driven around the lap, tracked through the start/end seam: it goes negative if the car
    backs up behind the start, and never jumps by a lap.

    ## Arguments

    | Argument    | Default          | Meaning                                                  |
    |-------------|------------------|----------------------------------------------------------|
    | world       | "open_cylinders" | "open_cylinders", "hallway", "closed_to_open", "random"; |
    |             |                  | a World; a 2-D array (0 free, > 0 obstacle, pixel size   |
    |             |                  | config map_resolution, 0.05 m); an image path; a ROS     |
    |             |                  | map_server YAML path (:mod:`lidar_env.world.ros_map`)    |
    | trace       | None             | "straight", "right_turn", "zigzag", "loop",              |
    |             |                  | "out_and_back"; None: the world's paper trace            |
    |             |                  | (right_turn, zigzag, zigzag, zigzag; straight in a user  |
    |             |                  | world); or a route: (N, 2) waypoints [m] or a Trace,     |
    |             |                  | checked for clearance and rounded                        |
    |             |                  | (:mod:`lidar_env.routes.user_traces`)                    |
    | config      | None             | an :class:`EnvConfig` or a dict of its fields; each      |
    |             |                  | Lidar's noise is set in ``config["lidars"]``; key        |
    |             |                  | "robot" starts from a preset ("paper_car",               |
    |             |                  | "turtlebot3_burger", "turtlebot3_waffle_pi", "f1tenth";  |
    |             |                  | :mod:`lidar_env.vehicle.presets`, docs/robots.md)        |
    | render_mode | None             | "rgb_array" (no window) or "human" (needs pygame): frames |
    |             |                  | config ``render_size`` (800) px on the long side         |

    ``reset(seed=..., options={"world": ..., "trace": ..., "start": (x, y, heading)})``
    changes the world, trace or start pose for that episode only. A ``random`` world is drawn
    from the env's ``np_random`` at every reset, as are range noise, dropouts and the movers
    (their places and speeds at reset, their waypoints during the episode; none without movers,
    so M = 0 leaves every random stream as before).
    ``env.unwrapped.space`` is the pymunk ``Space`` (obstacles, the car's and movers' kinematic
    bodies), ``.crowd`` the :class:`~lidar_env.movers.crowd.Crowd` (None without movers),
    ``.world`` the :class:`~lidar_env.world.world.World`, ``.trace`` the active
    :class:`~lidar_env.routes.traces.Trace`, ``.config`` the :class:`EnvConfig`.

    ## Version History

    * v0: initial version.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        world: str | World | Any = "open_cylinders",
        trace: str | ArrayLike | Trace | None = None,
        config: EnvConfig | Mapping[str, Any] | None = None,
        render_mode: str | None = None,
    ) -> None:
        self.trace_name = trace if trace is None or isinstance(trace, Trace) else (
            check_trace_name(trace) if isinstance(trace, str) else check_waypoints(trace))
        if isinstance(config, EnvConfig):
            self.config = config
        elif config is None or isinstance(config, Mapping):
            self.config = EnvConfig.from_dict(config)
        else:
            raise ArgumentTypeError(
                f"config: expected an EnvConfig or a dict, got {type(config).__name__}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                f"render_mode: expected one of {', '.join(self.metadata['render_modes'])} or "
                f"None, got {render_mode!r}"
            )
        self.render_mode = render_mode
        cfg = self.config
        self._world_arg = resolve_world(world, cfg.map_resolution)
        self._world_source = world  # a ROS map's path: its unknown cells are drawn apart
        self.world_name = (self._world_arg if isinstance(self._world_arg, str)
                           else self._world_arg.name)
        self.lidar_keys = tuple(f"lidar_{k + 1}" for k in range(cfg.n_lidars))
        self.observation_space = spaces.Dict({
            key: spaces.Box(0.0, lidar.max_range, (lidar.n_beams,), np.float32)
            for key, lidar in zip(self.lidar_keys, cfg.lidars, strict=True)
        })
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.lidar = LidarLayout(cfg.lidars, (cfg.car_length, cfg.car_width))
        announce_first_compile("DualLidar-v0's first reset",
                               (scan_packed_kernel, mount_poses, project_onto_polyline))
        self._mounts = cfg.mounts_array
        self._sensor_poses = np.zeros((cfg.n_lidars, 3))
        self._world_aligned = cfg.scan_frame == "world"
        self._scenes = SceneCache()
        self.world: World | None = None
        self.trace: Trace | None = None
        self.car: Car | None = None
        self._space: Any = None
        self._space_world: World | None = None
        self._space_movers: list = []
        self.crowd = (Crowd(cfg.moving_obstacles, cfg.mover_radius, cfg.mover_speed_range,
                            cfg.mover_model) if cfg.moving_obstacles else None)
        self._renderer: Any = None
        self._trajectories: dict[str, NDArray[np.float64]] = {}
        self._render_map: Any = None
        self._last_scans: list[NDArray[np.float32]] | None = None
        self._time = 0.0
        self._arc = 0.0
        self._episode_over = False

    # ------------------------------------------------------------------ episode
    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        super().reset(seed=seed)
        options = check_reset_options(options)
        scene = self._scenes.for_episode(options, self._world_arg, self.trace_name,
                                         self.config, self.np_random)
        if self.world is not scene.world:
            self.car = Car(self.config.car_length, self.config.car_width,
                           scene.world.circles, scene.world.segments)
        self.world, self.trace = scene.world, scene.trace
        assert self.car is not None
        self.car.place(self.trace.start_pose)
        if self.crowd is not None:
            self.crowd.spawn(self.world, self.trace.waypoints,
                             (*self.trace.start_pose, self.car.half_length, self.car.half_width),
                             self.config.mover_clearance, self.np_random)
        self._time = 0.0
        self._arc = 0.0
        self._episode_over = False
        self._trajectories = {}
        self._render_map = None
        observation = self._observe()
        info = self._info(*self._progress(), collision=False)
        if self.render_mode == "human":
            self.render()
        return observation, info

    def step(
        self, action: ArrayLike
    ) -> tuple[dict[str, NDArray[np.float32]], float, bool, bool, dict[str, Any]]:
        if self.car is None or self.trace is None:
            raise ResetNeededError("call reset() before step()")
        if self._episode_over:
            raise ResetNeededError(
                "step() after the episode ended (terminated or truncated): call reset() first")
        throttle, steer = checked_action(action)
        cfg = self.config
        speed = min(max(throttle, -1.0), 1.0) * cfg.max_speed
        yaw_rate = min(max(steer, -1.0), 1.0) * cfg.max_yaw_rate
        if self.crowd is None:
            collision = self.car.drive(speed, yaw_rate, cfg.control_dt, cfg.physics_substeps)
        else:  # movers first (their waypoint draws), then the car among them
            start = self.crowd.circles
            car = (None if cfg.mover_model == "waypoints" else car_circles(
                self.car.pose, self.car.half_length, self.car.half_width))
            self.crowd.step(self.world, cfg.control_dt, self.np_random, car)
            collision = self.car.drive(speed, yaw_rate, cfg.control_dt, cfg.physics_substeps,
                                       start, self.crowd.velocities, self.crowd.max_speed)
        self._time += cfg.control_dt
        previous_arc = self._arc
        arc, cross_track = self._progress()
        reward = arc - previous_arc - cfg.cross_track_penalty * abs(cross_track) * cfg.control_dt
        if collision:
            reward -= cfg.collision_penalty
        terminated = collision or arc >= self.trace.length - cfg.goal_tolerance
        truncated = not terminated and self._time >= cfg.max_episode_time - 1e-9
        observation = self._observe()
        info = self._info(arc, cross_track, collision)
        self._episode_over = terminated or truncated
        if self.render_mode == "human":
            self.render()
        return observation, reward, terminated, truncated, info

    def _progress(self) -> tuple[float, float]:
        """Arc position [m] and cross-track error [m] of the car, tracked near the last one."""
        assert self.car is not None and self.trace is not None
        pose = self.car.pose
        arc, cross_track = project_onto_polyline(
            self.trace.waypoints, self.trace.arc, pose[0], pose[1], self._arc, PROGRESS_WINDOW,
            self.trace.closed,
        )
        self._arc = arc
        return arc, cross_track

    def _observe(self) -> dict[str, NDArray[np.float32]]:
        assert self.car is not None
        mount_poses(self.car.pose, self._mounts, self._sensor_poses)
        cast_from = self._sensor_poses
        if self._world_aligned:
            cast_from = self._sensor_poses.copy()
            cast_from[:, 2] = 0.0  # beam i along world angle beam_angles[i]
        movers = None if self.crowd is None else self.crowd.circles
        scans = self.lidar.scan(self.world, cast_from, self.np_random, movers, self.car.pose)
        self._last_scans = scans
        return dict(zip(self.lidar_keys, scans, strict=True))

    def _info(self, arc: float, cross_track: float, collision: bool) -> dict[str, Any]:
        assert self.car is not None and self.trace is not None
        return {
            "pose": self.car.pose.copy(),
            "lidar_poses": self._sensor_poses.copy(),
            "time": self._time,
            "progress": arc / self.trace.length,
            "arc_position": arc,
            "cross_track_error": cross_track,
            "collision": collision,
            "moving_obstacles": np.zeros((0, 5)) if self.crowd is None else self.crowd.state,
        }
