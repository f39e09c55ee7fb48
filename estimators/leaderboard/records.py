"""What the experiment database stores, as plain dataclasses: a :class:`Scenario` (world, trace
seed, reset seed, driver, env config), the :class:`SensorDataset` recorded along it, an
estimator's :class:`TraceDataset` and a stored :class:`TraceRecord` with its metrics; and the
version every stored item carries (:func:`package_version`: the package version plus a digest
of the code, so that a changed estimator never reuses an old trace).
"""

from __future__ import annotations

import ast
import hashlib
import io
import json
import tokenize
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from estimators.base import SensorSetup
from estimators.paths import PROJECT_ROOT
from lidar_env.core import DatabaseError, kernel_cache

#: The packages whose code makes a trace (hashed into :func:`package_version`).
SOURCE_PACKAGES = ("agents", "estimators", "lidar_env")


def package_version() -> str:
    """The installed duallidar version and a digest of its source, e.g. ``0.1.0+src.1a2b3c4d5e6f``,
    recorded with every dataset and trace.

    The digest is why: an editable install keeps its version number while the code changes, and
    a stored trace must not stand in for an estimator that has changed since (a re-run then
    replays the stored sensor datasets through the new code)."""
    try:
        version = metadata.version("duallidar")
    except metadata.PackageNotFoundError:
        version = "0+unknown"
    return f"{version}+src.{code_digest(PROJECT_ROOT)}"


@lru_cache(maxsize=4)
def source_digest(root: Path, packages: tuple[str, ...] = SOURCE_PACKAGES) -> str:
    """SHA-256 (first 12 hex digits) of the paths and contents of the ``*.py`` files of
    ``packages`` under ``root``, read once per process (worker processes forked later inherit
    it, so one run has one version)."""
    return kernel_cache.source_digest(root, packages)


@lru_cache(maxsize=4)
def code_digest(root: Path, packages: tuple[str, ...] = SOURCE_PACKAGES) -> str:
    """SHA-256 (first 12 hex digits) of the code of the ``*.py`` files of ``packages`` under
    ``root``: their paths and tokens, without comments, docstrings or blank lines, so a change
    of wording changes no version and forces no re-run, while any change of code does."""
    digest = hashlib.sha256()
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            digest.update(path.relative_to(root).as_posix().encode())
            for token in _code_tokens(path.read_text()):
                digest.update(token.encode() + b"\0")
    return digest.hexdigest()[:12]


def _code_tokens(source: str) -> list[str]:
    """The tokens of ``source`` that are code (statement ends and indentation by their type):
    no comments, blank lines, continuation breaks or docstrings."""
    docstrings = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str)):
                docstrings.add((first.lineno, first.col_offset))
    structure = {tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT}
    tokens, after_docstring = [], False
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.STRING and token.start in docstrings:
            after_docstring = True  # its statement's end goes with it
        elif token.type == tokenize.NEWLINE and after_docstring:
            after_docstring = False
        elif token.type not in (tokenize.COMMENT, tokenize.NL):
            tokens.append(tokenize.tok_name[token.type] if token.type in structure
                          else token.string)
    return tokens


def canonical_json(value: Any) -> str:
    """Compact JSON with sorted keys, numpy scalars/arrays and tuples as plain lists/numbers.

    Used for configs and params so that equal settings give equal strings (UNIQUE keys).
    """

    def plain(item: Any) -> Any:
        if isinstance(item, np.ndarray):
            return item.tolist()
        if isinstance(item, np.generic):
            return item.item()
        raise TypeError(f"cannot store {type(item).__name__} {item!r} as JSON")

    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=plain)


@dataclass(frozen=True)
class Scenario:
    """One simulated (or recorded) run: world, trace seed, env seed, driver and env config.

    ``config`` holds the env config overrides passed to ``gym.make(..., config=...)``; it is
    part of the scenario's identity (two noise levels are two scenarios).
    """

    world: str
    trace: str
    seed: int
    config: Mapping[str, Any] = field(default_factory=dict)
    driver: str = "scripted"
    kind: str = "sim"

    def __hash__(self) -> int:  # config is a dict: hash its canonical JSON instead
        return hash((self.kind, self.world, self.trace, self.seed, self.driver, self.config_json))

    @property
    def config_json(self) -> str:
        return canonical_json(dict(self.config))

    @property
    def label(self) -> str:
        """Short human-readable name, e.g. ``hallway/zigzag/s0``; scans in another frame than
        the sensor's (the paper's world-aligned ones) add it: ``hallway/zigzag/s0/world``."""
        label = f"{self.world}/{self.trace}/s{self.seed}"
        frame = self.config.get("scan_frame", "sensor")
        return label if frame == "sensor" else f"{label}/{frame}"


@dataclass(frozen=True)
class SensorDataset:
    """What the Lidars saw along one scenario, with the ground truth beside it.

    Attributes:
        setup: the sensor geometry an estimator may know.
        times: ``(N,)`` observation times [s].
        scans: ``{key: (N, n_beams) float32}`` ranges [m] in each sensor's own frame, keyed by
            ``setup.keys``; ``>= setup.max_range`` means no return.
        poses: ``(N, 3)`` true car poses (x [m], y [m], heading [rad]) in the world frame.
        lidar_poses: ``(N, K, 3)`` true sensor poses in the world frame.
        env_config: every resolved env setting (JSON-able), for the record.
        world: the world map's geometry (``name``, ``circles`` (N, 3), ``walls`` (M, 4),
            ``polygons``, ``bounds``; metres, world frame), so the map can be drawn as it was
            when recorded; empty when unknown.
    """

    setup: SensorSetup
    times: NDArray[np.float64]
    scans: dict[str, NDArray[np.float32]]
    poses: NDArray[np.float64]
    lidar_poses: NDArray[np.float64]
    env_config: Mapping[str, Any] = field(default_factory=dict)
    world: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.times)
        if n < 1:
            raise DatabaseError("a sensor dataset needs at least one step, got 0")
        k, n_beams = self.setup.n_lidars, len(self.setup.beam_angles)
        if set(self.scans) != set(self.setup.keys):
            raise DatabaseError(f"scans: expected keys {self.setup.keys}, got {tuple(self.scans)}")
        for key, scan in self.scans.items():
            if scan.shape != (n, n_beams) or scan.dtype != np.float32:
                raise DatabaseError(
                    f"scans[{key!r}]: expected float32 ({n}, {n_beams}), "
                    f"got {scan.dtype} {scan.shape}"
                )
        if self.poses.shape != (n, 3):
            raise DatabaseError(f"poses: expected shape ({n}, 3), got {self.poses.shape}")
        if self.lidar_poses.shape != (n, k, 3):
            raise DatabaseError(
                f"lidar_poses: expected shape ({n}, {k}, 3), got {self.lidar_poses.shape}"
            )

    def __len__(self) -> int:
        return len(self.times)

    def observations(self) -> Iterator[dict[str, NDArray[np.float32]]]:
        """The observations in order, as the env emitted them."""
        for step in range(len(self)):
            yield {key: scan[step] for key, scan in self.scans.items()}


@dataclass(frozen=True)
class TraceDataset:
    """What one estimator made of one sensor dataset.

    Attributes:
        estimator: registered name; ``params``: every parameter it ran with (JSON-able).
        times: ``(N,)`` [s]; poses: ``(N, 3)`` estimated car poses (x [m], y [m], heading
        [rad]); step_ms: ``(N,)`` wall time of each ``update`` call [ms].
    """

    estimator: str
    params: Mapping[str, Any]
    times: NDArray[np.float64]
    poses: NDArray[np.float64]
    step_ms: NDArray[np.float64]
    package_version: str = field(default_factory=package_version)

    def __post_init__(self) -> None:
        n = len(self.times)
        if self.poses.shape != (n, 3) or self.step_ms.shape != (n,):
            raise DatabaseError(
                f"a trace of {n} times needs poses ({n}, 3) and step_ms ({n},), "
                f"got {self.poses.shape} and {self.step_ms.shape}"
            )

    @property
    def params_json(self) -> str:
        return canonical_json(dict(self.params))

    @property
    def ms_per_step(self) -> float:
        """Mean wall time [ms] of one ``update`` after the first (which only takes the scan),
        as :class:`estimators.evaluation.scoring.ScoreEstimator` reports it."""
        return float(np.mean(self.step_ms[1:] if len(self.step_ms) > 1 else self.step_ms))


@dataclass(frozen=True)
class TraceRecord:
    """A stored trace with its scenario and metrics (what :meth:`ExperimentDatabase.traces`
    returns)."""

    trace_id: int
    scenario: Scenario
    trace: TraceDataset
    metrics: dict[str, float]
