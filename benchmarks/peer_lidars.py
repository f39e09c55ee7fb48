"""Peers' 2D Lidars on our scene: IR-SIM's and VMAS's scans against our kernel, CPU time.

The scene is a 20 m x 20 m room of four walls, discs and rotated boxes placed from a seed with
a gap between any two, so no obstacle overlaps another or a wall: shapes every peer has, exact
in each but for IR-SIM's discs (below). Ours is a :class:`lidar_env.world.world.World` (the
walls as segments, the boxes as polygons) scanned by :func:`lidar_env.sensors.lidar.cast_rays`;
IR-SIM (PyPI ``ir-sim``) gets linestring walls, circle and rectangle obstacles and a
``lidar2d`` sensor whose ``Lidar2D.step`` is timed; VMAS (PyPI ``vmas``) gets ``Line``,
``Sphere`` and ``Box`` landmarks and an agent carrying a ``Lidar`` whose ``measure`` is timed,
torch on one thread. Every Lidar casts 360 beams 1 degree apart from the pose's heading, 10 m
range, noiseless, from the same random poses at least 0.3 m from any obstacle. Each call scans
one pose, or a batch of ``B`` poses: VMAS then scans ``B`` environments in one ``measure``,
ours casts ``B`` sensors in one ``cast_rays`` call, and IR-SIM, which has no batch, scans them
one after the other; the time per scan is the call's divided by ``B``.

Each scanner is charged the CPU time (``time.process_time``) of its scan calls (placing the
sensor at the pose and scanning; no physics step, no drawing), measured in blocks of poses in
turns (ours several passes over a block, then each peer once), so a shared machine's load
weighs on all alike, after an untimed pass over every pose that loads the kernels and keeps
each peer's ranges. Those ranges are compared with ours cast along the peer's own beam
directions: the median and maximum absolute difference [m] show the scene is the same. IR-SIM
draws a circle as a 64-gon (shapely's ``buffer``), which reads up to ``r (1 - cos(pi / 64))``
(1.2 mm per metre of radius) long on a disc face on, more on a beam that grazes it, and misses
some of those; VMAS computes in float32.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numba
import numpy as np
from numpy.typing import NDArray

from lidar_env.core import ConfigError
from lidar_env.sensors.lidar import Lidar, cast_rays
from lidar_env.world.world import World

ROOM_HALF_M = 10.0
#: Free space kept between any two obstacles and between an obstacle and a wall [m].
GAP_M = 0.5
#: A pose is free when it is at least this far from every obstacle [m].
POSE_CLEARANCE_M = 0.3
#: Passes of our kernel over each block for one pass of each peer (ours is far faster).
OUR_PASSES = 20
BLOCK = 10

Scan = Callable[[NDArray[np.float64]], NDArray[np.float64]]


@dataclass(frozen=True)
class Scene:
    """A walled room [m]: ``walls`` ``(4, 4)`` rows x1, y1, x2, y2; ``circles`` ``(N, 3)``
    rows cx, cy, r; ``boxes`` ``(M, 5)`` rows cx, cy, length (along the box's x), width,
    heading [rad]."""

    walls: NDArray[np.float64]
    circles: NDArray[np.float64]
    boxes: NDArray[np.float64]

    def box_corners(self) -> NDArray[np.float64]:
        """``(M, 4, 2)`` world corners of each box, counter-clockwise."""
        half = 0.5 * self.boxes[:, 2:4]
        local = np.stack([-half, half * [1, -1], half, half * [-1, 1]], axis=1)
        c, s = np.cos(self.boxes[:, 4])[:, None], np.sin(self.boxes[:, 4])[:, None]
        return np.stack([c * local[..., 0] - s * local[..., 1] + self.boxes[:, None, 0],
                         s * local[..., 0] + c * local[..., 1] + self.boxes[:, None, 1]],
                        axis=-1)

    def world(self) -> World:
        """Our world: the walls as segments, the boxes as polygons."""
        return World(self.circles, self.walls, list(self.box_corners()), name="peer room")


def make_scene(seed: int, n_circles: int = 6, n_boxes: int = 6) -> Scene:
    """The room with ``n_circles`` discs (r 0.3-1 m) and ``n_boxes`` boxes (sides 0.5-2 m,
    any heading), centres drawn from ``seed`` until every pair is :data:`GAP_M` apart."""
    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.3, 1.0, n_circles)
    sides = rng.uniform(0.5, 2.0, (n_boxes, 2))
    reach = np.concatenate([radii, 0.5 * np.hypot(sides[:, 0], sides[:, 1])])
    centres: list[NDArray[np.float64]] = []
    for _ in range(10_000):
        if len(centres) == len(reach):
            break
        k = len(centres)
        inner = ROOM_HALF_M - GAP_M - reach[k]
        centre = rng.uniform(-inner, inner, 2)
        if all(np.hypot(*(centre - c)) >= reach[k] + reach[j] + GAP_M
               for j, c in enumerate(centres)):
            centres.append(centre)
    if len(centres) < len(reach):
        raise RuntimeError(f"could not place {len(reach)} obstacles apart in the room")
    at = np.array(centres).reshape(-1, 2)
    corners = ROOM_HALF_M * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
    walls = np.hstack([corners, np.roll(corners, -1, axis=0)])
    boxes = np.column_stack([at[n_circles:], sides, rng.uniform(0, np.pi, n_boxes)])
    return Scene(walls, np.column_stack([at[:n_circles], radii]), boxes)


def free_poses(world: World, rng: np.random.Generator, count: int) -> NDArray[np.float64]:
    """``(count, 3)`` poses (x, y [m], heading [rad]) inside the room, each at least
    :data:`POSE_CLEARANCE_M` from every obstacle."""
    inner = ROOM_HALF_M - POSE_CLEARANCE_M
    poses = np.column_stack([rng.uniform(-inner, inner, (20 * count, 2)),
                             rng.uniform(-np.pi, np.pi, 20 * count)])
    free = poses[world.clearance(poses[:, :2]) >= POSE_CLEARANCE_M]
    if len(free) < count:
        raise RuntimeError(f"found only {len(free)} free poses, wanted {count}")
    return free[:count]


class PeerLidar(Protocol):
    """A peer's Lidar placed in the scene: ``scan(poses)`` returns the ``(B, n)`` ranges [m]
    of ``B`` sensors at ``poses`` ``(B, 3)`` (``B`` fixed when the peer is made);
    ``beam_angles`` are its beams' directions [rad] from a pose's heading."""

    name: str
    version: str
    settings: dict[str, Any]
    beam_angles: NDArray[np.float64]

    def scan(self, poses: NDArray[np.float64]) -> NDArray[np.float64]: ...


class IrSimLidar:
    """IR-SIM's ``lidar2d`` on a robot in the scene, written as a world file and loaded by
    ``irsim.make``, headless. Its beams span ``angle_range`` centred on its heading, so the
    heading is turned by half the span to put beam 0 on the pose's heading. IR-SIM scans one
    sensor per call: a batch of poses is scanned one after the other."""

    name = "IR-SIM"

    def __init__(self, scene: Scene, n_beams: int, max_range: float, batch: int = 1) -> None:
        import irsim

        span = 2 * math.pi * (n_beams - 1) / n_beams
        self.turn = 0.5 * span
        shapes = ([{"shape": {"name": "linestring", "vertices": [w[:2].tolist(), w[2:].tolist()]},
                    "state": [0.0, 0.0, 0.0]} for w in scene.walls]
                  + [{"shape": {"name": "circle", "radius": float(r)},
                      "state": [float(x), float(y), 0.0]} for x, y, r in scene.circles]
                  + [{"shape": {"name": "rectangle", "length": float(b[2]), "width": float(b[3])},
                      "state": [float(b[0]), float(b[1]), float(b[4])]} for b in scene.boxes])
        lidar = {"name": "lidar2d", "range_min": 0.0, "range_max": float(max_range),
                 "angle_range": span, "number": n_beams, "noise": False}
        config = {"world": {"height": 2 * ROOM_HALF_M, "width": 2 * ROOM_HALF_M,
                            "offset": [-ROOM_HALF_M, -ROOM_HALF_M]},
                  "robot": [{"kinematics": {"name": "diff"},
                             "shape": {"name": "circle", "radius": 0.05},
                             "state": [0.0, 0.0, 0.0], "sensors": [lidar]}],
                  "obstacle": [{"number": 1, **shape} for shape in shapes]}
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "peer_room.yaml"
            path.write_text(json.dumps(config))  # JSON is YAML
            self.env = irsim.make(str(path), display=False, disable_all_plot=True, log_file=None,
                                  log_level="ERROR")
        self.lidar = self.env.robot.sensors[0]
        self.beam_angles = self.turn + np.asarray(self.lidar.angle_list, dtype=np.float64)
        self.version = irsim.__version__
        self.settings = {"call": "Lidar2D.step(state)", "angle_range_rad": span,
                         "number": n_beams, "range_max_m": max_range, "noise": False,
                         "circles": "shapely buffer, 64-gon"}

    def scan(self, poses: NDArray[np.float64]) -> NDArray[np.float64]:
        ranges = np.empty((len(poses), self.lidar.number))
        for k, (x, y, heading) in enumerate(poses):
            self.lidar.step(np.array([[x], [y], [heading + self.turn]]))
            ranges[k] = self.lidar.range_data
        return ranges


class VmasLidar:
    """VMAS's ``Lidar`` on an agent in a world of landmarks batched over ``batch``
    environments, torch on one thread; the agent is placed at each environment's pose, then one
    ``measure`` scans them all."""

    name = "VMAS"

    def __init__(self, scene: Scene, n_beams: int, max_range: float, batch: int = 1) -> None:
        import torch
        import vmas
        from vmas.simulator.core import Agent, Box, Landmark, Line, Sphere
        from vmas.simulator.core import World as VmasWorld
        from vmas.simulator.sensors import Lidar as VmasSensor

        torch.set_num_threads(1)
        self.torch = torch
        world = VmasWorld(batch_dim=batch, device=torch.device("cpu"))
        self.sensor = VmasSensor(world, n_rays=n_beams, max_range=max_range, render=False)
        self.agent = Agent("lidar", shape=Sphere(0.05), sensors=[self.sensor])
        world.add_agent(self.agent)
        placed: list[tuple[Any, list[float], float]] = []
        for x1, y1, x2, y2 in scene.walls:
            placed.append((Line(float(np.hypot(x2 - x1, y2 - y1))),
                           [0.5 * (x1 + x2), 0.5 * (y1 + y2)], math.atan2(y2 - y1, x2 - x1)))
        placed += [(Sphere(float(r)), [x, y], 0.0) for x, y, r in scene.circles]
        placed += [(Box(float(b[2]), float(b[3])), [b[0], b[1]], float(b[4]))
                   for b in scene.boxes]
        for k, (shape, xy, heading) in enumerate(placed):
            landmark = Landmark(f"obstacle_{k}", shape=shape)
            world.add_landmark(landmark)
            landmark.set_pos(torch.tensor([xy], dtype=torch.float32), batch_index=None)
            landmark.set_rot(torch.tensor([[heading]], dtype=torch.float32), batch_index=None)
        self.beam_angles = self.sensor._angles[0].double().numpy()
        self.version = vmas.__version__
        self.settings = {"call": "Lidar.measure()", "n_rays": n_beams, "max_range_m": max_range,
                         "batch_dim": batch, "torch": torch.__version__, "torch_threads": 1,
                         "dtype": "float32"}

    def scan(self, poses: NDArray[np.float64]) -> NDArray[np.float64]:
        placed = self.torch.from_numpy(poses.astype(np.float32))
        self.agent.state.pos, self.agent.state.rot = placed[:, :2], placed[:, 2:]
        return self.sensor.measure().double().numpy()


#: Peer name -> (module to import, pip install command, adapter).
PEERS: dict[str, tuple[str, str, Callable[[Scene, int, float, int], PeerLidar]]] = {
    "ir-sim": ("irsim", "pip install ir-sim", IrSimLidar),
    "vmas": ("vmas", "pip install torch vmas", VmasLidar),
}


def importable_peers(names: list[str]) -> tuple[list[str], list[str]]:
    """The peers among ``names`` whose module imports, and one line for each that does not."""
    found, skipped = [], []
    for name in names:
        module, install, _ = PEERS[name]
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # IR-SIM prints its GUI backends
                importlib.import_module(module)
        except ImportError as error:
            skipped.append(f"{name} skipped: cannot import {module} ({error}); install it with "
                           f"'{install}', or give --peers-path DIR holding it")
        else:
            found.append(name)
    return found, skipped


def our_scanner(world: World, lidar: Lidar) -> Scan:
    """Our exact ranges of sensors at poses ``(B, 3)``, all in one call, as the env casts them."""
    angles, max_range = lidar.beam_angles, lidar.max_range
    return lambda poses: cast_rays(world, poses, angles, max_range)


def interleaved_cpu(scans: dict[str, Scan], batches: NDArray[np.float64],
                    passes: dict[str, int], block: int = BLOCK) -> dict[str, float]:
    """CPU time [us] per scan (per pose) of each scanner called on ``batches`` ``(G, B, 3)``,
    timed in turns: for each block of ``block`` batches, ``passes[name]`` passes of each
    scanner over the block."""
    spent = dict.fromkeys(scans, 0.0)
    calls = dict.fromkeys(scans, 0)
    clock = time.process_time
    for start in range(0, len(batches), block):
        part = batches[start:start + block]
        for name, scan in scans.items():
            begin = clock()
            for _ in range(passes[name]):
                for poses in part:
                    scan(poses)
            spent[name] += clock() - begin
            calls[name] += passes[name] * len(part)
    return {name: 1e6 * spent[name] / (calls[name] * batches.shape[1]) for name in scans}


def disc_hits(scene: Scene, poses: NDArray[np.float64], angles: NDArray[np.float64],
              ranges: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(poses, beams)``: which of our beams end on a disc's surface (within 1 um)."""
    heading = poses[:, 2:3] + angles
    ends = poses[:, None, :2] + ranges[..., None] * np.stack([np.cos(heading), np.sin(heading)],
                                                               axis=-1)
    if not len(scene.circles):
        return np.zeros(ranges.shape, dtype=bool)
    gaps = np.linalg.norm(ends[..., None, :] - scene.circles[:, :2], axis=-1) - scene.circles[:, 2]
    return np.min(np.abs(gaps), axis=-1) < 1e-6


def agreement(peer: NDArray[np.float64], ours: NDArray[np.float64], on_disc: NDArray[np.bool_],
              tolerance: float) -> dict[str, float]:
    """Median and maximum absolute difference [m] of two ``(poses, beams)`` range arrays, the
    maximum over the beams that end off the discs (walls, boxes, misses), and how many beams
    differ by more than ``tolerance`` [m]."""
    difference = np.abs(peer - ours)
    off = difference[~on_disc]
    return {"median_abs_m": float(np.median(difference)), "max_abs_m": float(difference.max()),
            "max_abs_off_discs_m": float(off.max()) if off.size else 0.0,
            "within_m": tolerance, "beams": int(difference.size),
            "beyond": int(np.count_nonzero(difference > tolerance))}


#: Within which [m] a peer's beam counts as agreeing: IR-SIM's 64-gon discs (r <= 1 m), VMAS's
#: float32 arithmetic on a 10 m scan.
TOLERANCE_M = {"IR-SIM": 2e-3, "VMAS": 1e-4}


def bench_scene(peers: list[PeerLidar], scene: Scene, batches: NDArray[np.float64],
                lidar: Lidar) -> dict[str, Any]:
    """Time our kernel and every peer on ``batches`` of poses ``(G, B, 3)``, one call per batch,
    and check each peer's ranges against ours."""
    world = scene.world()
    poses = batches.reshape(-1, 3)
    scans: dict[str, Scan] = {"ours": our_scanner(world, lidar)}
    scans.update({peer.name: peer.scan for peer in peers})
    result: dict[str, Any] = {
        "poses": len(poses), "batch": batches.shape[1], "beams": lidar.n_beams,
        "max_range_m": lidar.max_range,
        "ours": {"call": "lidar_env.sensors.lidar.cast_rays(world, poses, angles, max_range)",
                 "passes_per_block": OUR_PASSES, "block_batches": _block(batches),
                 "numba": numba.__version__, "numpy": np.__version__},
        "agreement": {}, "peers": {}}
    for peer in peers:  # the untimed pass: loads the kernels and keeps the ranges
        theirs = np.concatenate([peer.scan(part) for part in batches])
        ours = cast_rays(world, poses, peer.beam_angles, lidar.max_range)
        on_disc = disc_hits(scene, poses, peer.beam_angles, ours)
        result["agreement"][peer.name] = agreement(theirs, ours, on_disc, TOLERANCE_M[peer.name])
        result["peers"][peer.name] = {"version": peer.version, "settings": peer.settings}
    for part in batches:
        scans["ours"](part)
    passes = {name: OUR_PASSES if name == "ours" else 1 for name in scans}
    per_scan = interleaved_cpu(scans, batches, passes, _block(batches))
    result["cpu_us_per_scan"] = per_scan
    result["ratios"] = {f"{peer.name}/ours": per_scan[peer.name] / per_scan["ours"]
                        for peer in peers}
    return result


def _block(batches: NDArray[np.float64]) -> int:
    """Batches per block: :data:`BLOCK` poses, at least one batch."""
    return max(1, BLOCK // batches.shape[1])


def run(names: list[str], seed: int, count: int,
        batch: int = 1) -> tuple[dict[str, Any], list[str]]:
    """The scene of ``seed``, ``count`` free poses (rounded down to whole batches of
    ``batch``), and :func:`bench_scene` over the importable peers among ``names``; also the
    lines naming the peers skipped."""
    if not 1 <= batch <= count:
        raise ConfigError(f"batch: expected 1 to {count} poses (the count), got {batch}")
    found, skipped = importable_peers(names)
    scene = make_scene(seed)
    lidar = Lidar()
    poses = free_poses(scene.world(), np.random.default_rng(seed), count - count % batch)
    peers = [PEERS[name][2](scene, lidar.n_beams, lidar.max_range, batch) for name in found]
    result = bench_scene(peers, scene, poses.reshape(-1, batch, 3), lidar)
    result["scene"] = {"seed": seed, "room_m": 2 * ROOM_HALF_M, "circles": len(scene.circles),
                       "boxes": len(scene.boxes), "pose_clearance_m": POSE_CLEARANCE_M}
    return result, skipped


def print_result(result: dict[str, Any]) -> None:
    """Per scanner: CPU us per scan, the ratio to ours and the agreement with ours."""
    scene = result["scene"]
    print(f"scene: {scene['room_m']:g} m room, {scene['circles']} discs, {scene['boxes']} boxes "
          f"(seed {scene['seed']}); {result['poses']} poses, {result['batch']} a call; "
          f"{result['beams']} beams, {result['max_range_m']:g} m")
    print(f"  {'ours':15s} {result['cpu_us_per_scan']['ours']:10.1f} us/scan CPU")
    for name, peer in result["peers"].items():
        agree = result["agreement"][name]
        print(f"  {name + ' ' + peer['version']:15s} {result['cpu_us_per_scan'][name]:10.1f} "
              f"us/scan CPU  {result['ratios'][name + '/ours']:6.0f}x ours")
        print(f"    |range - ours| median {agree['median_abs_m']:.1e} m, max "
              f"{agree['max_abs_m']:.1e} m ({agree['max_abs_off_discs_m']:.1e} m off the discs), "
              f"{agree['beyond']} of {agree['beams']} beams beyond {agree['within_m']:g} m")
