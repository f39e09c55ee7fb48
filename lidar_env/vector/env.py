"""``DualLidarVectorEnv``: N ``DualLidar-v0`` cars stepped in one compiled call, reached through
``gym.make_vec("DualLidar-v0", num_envs=N, vectorization_mode="vector_entry_point")``."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from lidar_env.config import EnvConfig
from lidar_env.core.errors import ConfigError, ResetNeededError, quoted
from lidar_env.core.kernel_cache import announce_first_compile
from lidar_env.env import PROGRESS_WINDOW, DualLidarEnv
from lidar_env.routes.trace_geometry import Trace, project_onto_polyline
from lidar_env.scenes import SceneCache, check_reset_options
from lidar_env.vector.crowds import CrowdSlots
from lidar_env.vector.entry_point import EntryPoint
from lidar_env.vector.kernel import observe_envs, step_batch
from lidar_env.vector.slots import SceneSlots
from lidar_env.vehicle.car import MAX_STEP_FRACTION, MAX_SUBSTEPS, Car
from lidar_env.world.world import World

Observation = dict[str, NDArray[np.float32]]

#: Most sub-envs one batched env holds: its arrays are allocated up front (at 1,440 beams,
#: 65,536 sub-envs hold 0.4 GB of scans).
MAX_NUM_ENVS = 65_536


class VectorResetNeededError(ResetNeededError, gym.error.ResetNeeded):
    """``step()`` before every sub-env was reset: our :class:`ResetNeededError` and
    Gymnasium's ``ResetNeeded`` alike, so either ``except`` clause catches it."""


def not_batched(config: EnvConfig) -> str | None:
    """Why the batched env cannot run ``config`` yet (the ConfigError it raises), or None."""
    occluded = [k for k, lidar in enumerate(config.lidars) if lidar.self_occlusion]
    if occluded:
        return (f"lidars[{occluded[0]}].self_occlusion: not batched yet; the batched env "
                "expected False; use vectorization_mode='sync' for self-occluded Lidars")
    return None


class DualLidarVectorEnv(VectorEnv):
    """``num_envs`` independent ``DualLidar-v0`` episodes, stepped together.

    Each sub-env behaves bit for bit like one :class:`~lidar_env.env.DualLidarEnv` built with
    the same ``world``, ``trace`` and ``config`` and reset with the same seed, inside a
    ``gymnasium.vector.SyncVectorEnv``: same observations, rewards, terminations,
    truncations and infos (see that class for their meaning and units). Observations are a
    ``Dict`` of ``(num_envs, n_beams_k)`` float32 scans, actions a ``(num_envs, 2)`` Box in
    [-1, 1], infos a dict of ``(num_envs, ...)`` arrays each with its ``_key`` mask, as
    ``SyncVectorEnv`` batches them; every returned array is new (later steps never change it)
    and shares no memory with the env or another output.

    Autoreset (``metadata["autoreset_mode"]``) is Gymnasium's ``NEXT_STEP``: the step after a
    sub-env terminates or truncates resets it (its action is ignored) and returns its reset
    observation and info with reward 0 and no termination or truncation.
    ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (or ``seed=[s_0, ...]``; seeds >= 0);
    ``options`` (world, trace, start, as for the single env) apply to every sub-env reset,
    and ``options["reset_mask"]`` (bool ``(num_envs,)``) resets only those sub-envs (so each
    can start with its own options); ``step()`` needs every sub-env reset once (else a
    :class:`VectorResetNeededError`, which is both our ``ResetNeededError`` and Gymnasium's
    ``ResetNeeded``). At most :data:`MAX_NUM_ENVS` sub-envs.

    Differences from ``SyncVectorEnv``: a bad action (wrong shape, NaN or inf in the action of
    a sub-env that steps) raises a ``ConfigError`` before any sub-env moves, where
    ``SyncVectorEnv`` has stepped the sub-envs before the bad one; what is not batched yet is
    refused by name with a ``ConfigError`` (rendering: ``render_mode`` must be None;
    self-occluded Lidars). Moving obstacles (``config["moving_obstacles"]``) are batched: each
    sub-env's crowd steps inside the same call, drawing its waypoints from the sub-env's
    generator before its scans, as the single env does; ``info["moving_obstacles"]`` is
    ``(num_envs, M, 5)``. The env pickles mid-episode, as the single env does (numba's typed
    lists and entry points are rebuilt on unpickling; the generators keep their states).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        world: str | World | Any = "open_cylinders",
        trace: str | ArrayLike | Trace | None = None,
        config: EnvConfig | Mapping[str, Any] | None = None,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or not 1 <= num_envs <= MAX_NUM_ENVS:
            raise ConfigError(f"num_envs: expected an integer in 1 .. {MAX_NUM_ENVS}, got "
                              f"{quoted(num_envs)}")
        if render_mode is not None:
            raise ConfigError(f"render_mode: the batched env does not render (not batched "
                              f"yet); expected None, got {render_mode!r}; render a single "
                              "DualLidar-v0 or use vectorization_mode='sync'")
        single = DualLidarEnv(world, trace, config)  # checks world, trace and config alike
        reason = not_batched(single.config)
        if reason is not None:
            raise ConfigError(reason)
        # the single env reports its movers (maybe none) in every info once it has them
        self._mover_info = hasattr(single.config, "moving_obstacles")
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.config = cfg = single.config
        self.single_observation_space = single.observation_space
        self.single_action_space = single.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.lidar_keys = single.lidar_keys
        self._world_arg, self._trace_arg = single._world_arg, single.trace_name
        self._scenes = SceneCache()
        self._slots = SceneSlots(self.num_envs)
        announce_first_compile("the batched DualLidar-v0's first reset",
                               (observe_envs, step_batch))
        self._car = Car(cfg.car_length, cfg.car_width, np.empty((0, 3)), np.empty((0, 4)))
        layout = single.lidar
        beams, params = layout._packed
        self._sensors = (cfg.mounts_array, cfg.scan_frame == "world",
                         bool(np.any(layout.noise_std > 0)), bool(np.any(layout.dropout_prob > 0)),
                         beams, params)
        ends = np.cumsum(layout.sizes)
        self._beam_slices = tuple(zip(ends - np.asarray(layout.sizes), ends, strict=True))
        self._constants = np.array([
            cfg.control_dt, self._car.half_length, self._car.half_width,
            cfg.cross_track_penalty, cfg.collision_penalty, cfg.goal_tolerance,
            cfg.max_episode_time - 1e-9, PROGRESS_WINDOW], dtype=np.float64)
        n, k = self.num_envs, cfg.n_lidars
        self._pose = np.zeros((n, 3))
        self._sensor_poses = np.zeros((n, k, 3))
        self._time = np.zeros(n)
        self._arc = np.zeros(n)
        self._progress = np.zeros(n)
        self._cross_track = np.zeros(n)
        self._collision = np.zeros(n, dtype=np.bool_)
        self._scans = np.zeros((n, int(ends[-1])), dtype=np.float32)
        self._scan_views = self._views()
        self._cast_from = np.zeros((k, 3))  # the scans' scratch: sensor poses [m, rad], draws
        self._draws = np.zeros(4 * int(ends[-1]))
        self._rewards = np.zeros(n)
        self._terminations = np.zeros(n, dtype=np.bool_)
        self._truncations = np.zeros(n, dtype=np.bool_)
        self._autoreset_envs = np.zeros(n, dtype=np.bool_)
        self._resetting = 0  # how many are True
        self._ready = np.zeros(n, dtype=np.bool_)  # reset at least once
        self._all_ready = False
        self._every_env = np.arange(n, dtype=np.int64)
        self._action_shape = (n, 2)
        self._observe_envs, self._step_batch = EntryPoint(observe_envs), EntryPoint(step_batch)
        self._stepper: tuple[Callable[..., tuple[int, int]], tuple] | None = None  # _bind's
        #: the info masks, one row per info key (:meth:`_infos`)
        self._all_present = np.ones((7 + self._mover_info, n), dtype=np.bool_)
        car = self._car  # the limits of Car.substeps_for, computed as it computes them
        self._limits = np.array([
            cfg.max_speed, cfg.max_yaw_rate, cfg.control_dt,
            math.hypot(car.half_length, car.half_width),
            MAX_STEP_FRACTION * 2.0 * min(car.half_length, car.half_width)], dtype=np.float64)
        self._speed, self._yaw_rate = np.zeros(n), np.zeros(n)
        self._checks = np.ones(n, dtype=np.int64)
        self._crowds = CrowdSlots(n, cfg, self._car.half_length, self._car.half_width)

    def __getstate__(self) -> dict[str, Any]:
        # the kernel's arguments hold numba typed lists, and the scan views must stay views
        return {**self.__dict__, "_stepper": None, "_scan_views": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._scan_views = self._views()

    def _views(self) -> tuple[tuple[str, NDArray[np.float32]], ...]:
        """Each Lidar's key and its columns of ``_scans`` (a view)."""
        return tuple((key, self._scans[:, a:b])
                     for key, (a, b) in zip(self.lidar_keys, self._beam_slices, strict=True))

    @property
    def worlds(self) -> list[World | None]:
        """Each sub-env's current :class:`~lidar_env.world.world.World`."""
        return list(self._slots.worlds)

    @property
    def traces(self) -> list[Trace | None]:
        """Each sub-env's current :class:`~lidar_env.routes.traces.Trace`."""
        return list(self._slots.traces)

    def trace_of(self, i: int) -> Trace | None:
        """Sub-env ``i``'s current trace (None before the first reset)."""
        return self._slots.traces[i]

    # ------------------------------------------------------------------ reset
    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: Mapping[str, Any] | None = None,
    ) -> tuple[Observation, dict[str, Any]]:
        seeds = self._seeds(seed)
        options = dict(options or {})
        mask = self._reset_mask(options.pop("reset_mask", None))
        if isinstance(seed, int):
            super().reset(seed=seed)
        envs = np.flatnonzero(mask)
        for i in envs:
            self._reset_env(int(i), seeds[i], options)
        self._observe(envs)
        self._terminations[mask] = False
        self._truncations[mask] = False
        self._autoreset_envs[mask] = False
        self._resetting = int(np.count_nonzero(self._autoreset_envs))
        self._ready |= mask
        self._all_ready = bool(self._ready.all())
        return self._observation(), self._infos(mask)

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            if seed < 0:
                raise ConfigError(f"seed: expected an integer >= 0 (sub-env i gets seed + i), "
                                  f"got {quoted(seed)}")
            return [int(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, Sequence) and not isinstance(seed, str):
            if len(seed) != self.num_envs:
                raise ConfigError(f"seed: expected {self.num_envs} seeds (one per sub-env), got "
                                  f"{len(seed)}")
            for i, value in enumerate(seed):
                if value is not None and (isinstance(value, bool) or not isinstance(
                        value, (int, np.integer)) or value < 0):
                    raise ConfigError(f"seed[{i}]: expected an integer >= 0 or None, got "
                                      f"{quoted(value)}")
            return [None if value is None else int(value) for value in seed]
        raise ConfigError(f"seed: expected an int, a list of {self.num_envs} or None, got "
                          f"{quoted(seed)}")

    def _reset_mask(self, mask: Any) -> NDArray[np.bool_]:
        if mask is None:
            return np.ones(self.num_envs, dtype=np.bool_)
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ \
                or mask.shape != (self.num_envs,) or not mask.any():
            raise ConfigError(f"options['reset_mask']: expected a bool numpy array of shape "
                              f"({self.num_envs},) with at least one True, got {mask!r:.80}")
        return mask

    def _reset_env(self, i: int, seed: int | None, options: Mapping[str, Any]) -> None:
        """Sub-env ``i``'s reset (``DualLidarEnv.reset`` up to its scans, which
        :meth:`_observe` takes for all reset sub-envs at once)."""
        slots = self._slots
        self._stepper = None  # a new scene may bring new scratch arrays
        if seed is not None or slots.generators[i] is None:
            slots.set_generator(i, seeding.np_random(seed)[0])
        rng = slots.generators[i]
        checked = check_reset_options(options)
        scene = self._scenes.for_episode(checked, self._world_arg, self._trace_arg, self.config,
                                         rng)
        slots.set(i, scene.world, scene.trace)
        self._crowds.spawn(i, scene.world, scene.trace, rng)
        trace = scene.trace
        self._pose[i] = trace.start_pose
        self._time[i] = 0.0
        self._collision[i] = False
        arc, cross_track = project_onto_polyline(trace.waypoints, trace.arc, self._pose[i, 0],
                                                 self._pose[i, 1], 0.0, PROGRESS_WINDOW,
                                                 trace.closed)
        self._arc[i], self._cross_track[i] = arc, cross_track
        self._progress[i] = arc / trace.length

    def _observe(self, envs: NDArray[np.int64]) -> None:
        if len(envs):
            self._observe_envs(envs.astype(np.int64), self._pose, self._sensor_poses, self._scans,
                               self._slots.scene, self._sensors, self._work(), self._crowds.kernel)

    def _work(self) -> tuple:
        """The kernels' scratch: ``(sensor poses (K, 3), draws (4 total beams,), circle and
        segment seen marks, next stamp (1,), near circles, near segments)`` (see
        :class:`~lidar_env.vector.slots.SceneSlots`); :func:`~lidar_env.vector.kernel.
        observe_envs` uses the first five."""
        slots = self._slots
        return (self._cast_from, self._draws, slots.circle_seen, slots.segment_seen,
                slots.stamp, slots.near_circles, slots.near_segments)

    # ------------------------------------------------------------------ step
    def step(
        self, actions: ArrayLike
    ) -> tuple[Observation, NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_],
               dict[str, Any]]:
        if not self._all_ready:
            never = np.flatnonzero(~self._ready)
            raise VectorResetNeededError(
                f"call reset() before step(): every sub-env must be reset once; sub-envs "
                f"{quoted(never.tolist())} never were ({len(never)} of {self.num_envs})")
        a = self._actions(actions)
        resetting = self._autoreset_envs.copy() if self._resetting else None
        stepping = self._every_env if resetting is None else np.flatnonzero(~resetting)
        step, args = self._stepper or self._bind()
        code, ended = step(a, stepping, *args)
        if code != -1:
            self._refuse(a, code)  # nothing moved, nothing was reset
        if resetting is not None:
            self._autoreset(resetting)
        if ended or resetting is not None:
            np.logical_or(self._terminations, self._truncations, out=self._autoreset_envs)
            self._resetting = ended
        return (self._observation(), self._rewards.copy(), self._terminations.copy(),
                self._truncations.copy(), self._infos(None))

    def _autoreset(self, resetting: NDArray[np.bool_]) -> None:
        """Reset the ``resetting`` sub-envs (their episode ended at the step before; the
        others have stepped: each sub-env draws from its own generator, so the order does not
        matter) with reward 0 and no episode end."""
        envs = np.flatnonzero(resetting)
        for i in envs:
            self._reset_env(int(i), None, {})
        self._observe(envs)
        self._rewards[resetting] = 0.0
        self._terminations[resetting] = False
        self._truncations[resetting] = False

    def _bind(self) -> tuple[Callable[..., tuple[int, int]], tuple]:
        """:func:`~lidar_env.vector.kernel.step_batch`'s machine code and its arguments after
        the actions and envs, kept until a sub-env's reset."""
        state = (self._pose, self._sensor_poses, self._time, self._arc, self._progress,
                 self._cross_track, self._collision, self._scans)
        args = (self._limits, self.config.physics_substeps, MAX_SUBSTEPS, self._crowds.max_speed,
                (self._speed, self._yaw_rate, self._checks), state,
                (self._rewards, self._terminations, self._truncations), self._slots.scene,
                self._sensors, self._work(), self._constants, self._crowds.kernel)
        self._stepper = self._step_batch.resolve(np.zeros((self.num_envs, 2)), self._every_env,
                                                 *args), args
        return self._stepper

    def _actions(self, actions: ArrayLike) -> NDArray[np.float64]:
        """``actions`` as a C-contiguous float64 ``(num_envs, 2)`` array, or a ConfigError."""
        try:
            a = np.ascontiguousarray(actions, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ConfigError(f"{self._expected_actions()} of numbers in [-1, 1], got "
                              f"{actions!r:.60}") from error
        if a.shape != self._action_shape:
            raise ConfigError(f"{self._expected_actions()}, got shape {a.shape}")
        return a

    def _expected_actions(self) -> str:
        return f"actions: expected shape ({self.num_envs}, 2) (speed, yaw rate per sub-env)"

    def _refuse(self, a: NDArray[np.float64], code: int) -> None:
        """The ConfigError naming the bad action behind :func:`~lidar_env.vector.kernel.
        plan_motion`'s ``code`` (nothing for -1)."""
        if code <= -2:
            row = -2 - code
            raise ConfigError(f"actions[{row}]: expected finite values in [-1, 1], got "
                              f"{a[row].tolist()}")
        if code >= 0:  # the single car's own check words the error
            cfg = self.config
            speed = min(max(float(a[code, 0]), -1.0), 1.0) * cfg.max_speed
            yaw_rate = min(max(float(a[code, 1]), -1.0), 1.0) * cfg.max_yaw_rate
            self._car.substeps_for(speed, yaw_rate, cfg.control_dt, cfg.physics_substeps,
                                   float(self._crowds.max_speed[code]))

    # ------------------------------------------------------------------ outputs
    def _observation(self) -> Observation:
        return {key: view.copy() for key, view in self._scan_views}

    def _infos(self, mask: NDArray[np.bool_] | None) -> dict[str, Any]:
        """The infos of every sub-env (``mask`` None) or of the ``mask`` ones, batched like
        ``SyncVectorEnv`` does (zeros and a False ``_key`` where a sub-env has none): new
        arrays, each key with its own mask, in the single env's key order."""
        values = (self._pose.copy(), self._sensor_poses.copy(), self._time.copy(),
                  self._progress.copy(), self._arc.copy(), self._cross_track.copy(),
                  self._collision.copy())
        if mask is None:
            masks = tuple(self._all_present.copy())
        else:
            masks = tuple(np.repeat(mask[None], len(self._all_present), axis=0))
            absent = ~mask
            for array in values:
                array[absent] = 0
        infos = {"pose": values[0], "_pose": masks[0], "lidar_poses": values[1],
                 "_lidar_poses": masks[1], "time": values[2], "_time": masks[2],
                 "progress": values[3], "_progress": masks[3], "arc_position": values[4],
                 "_arc_position": masks[4], "cross_track_error": values[5],
                 "_cross_track_error": masks[5], "collision": values[6], "_collision": masks[6]}
        if self._mover_info:  # x, y, vx, vy, radius of each mover
            infos["moving_obstacles"] = self._crowds.state(mask)
            infos["_moving_obstacles"] = masks[7]
        return infos
