"""The run's configuration as a reader wants it in the report (:func:`describe_settings`): one
``(option, value)`` pair per command-line option, named as typed (``--real-scans``), with
values in words: lists comma-separated, switches as yes/no, an option left out as what it
defaults to, a real log as its file, scan count and ground truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

#: What an option left out (None) means, by option.
UNSET: dict[str, str] = {
    "worlds": "the default matrix: the paper's groups and the hallway drives",
    "traces": "the default matrix: the paper's world/trace pairs",
    "estimators": "every registered estimator",
    "db": "experiments.sqlite in the output directory",
    "scheduler": "local worker processes",
    "real_log": "the Radish ACES log when it is there",
    "topics": "every LaserScan topic",
    "real_scans": "the first 1,000 ACES scans, all of --real-log",
}
#: Entries of the parsed arguments that are no option (shown elsewhere or not at all).
HIDDEN = frozenset({"argv", "logs", "func", "command"})


def describe_value(value: object) -> str:
    """``value`` in words: None as "not given", a bool as yes/no, a float without trailing
    zeros, a sequence comma-separated, a path as written, anything else as ``str``."""
    if value is None:
        return "not given"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}" if math.isfinite(value) else str(value)
    if isinstance(value, (Path, str)):
        return str(value)
    if isinstance(value, Sequence | frozenset | set):
        return ", ".join(describe_value(item) for item in value) or "none"
    return str(value)


def describe_log(log: object) -> str:
    """A real log (:class:`estimators.leaderboard.real_logs.RealLog`, read by attribute) in
    words: its name, file, how many scans and what it is scored on."""
    name = getattr(log, "name", None)
    path = getattr(log, "log_path", None)
    if name is None or path is None:
        return str(log)
    scans = getattr(log, "scans", None)
    relations = getattr(log, "relations_path", None)
    topic = getattr(log, "truth_topic", None)
    truth = (f"relations {Path(relations).name}" if relations
             else f"ground-truth topic {topic}" if topic else "no ground truth")
    count = "all scans" if not scans else f"first {scans:,} scans"
    return f"{str(name).upper()}: {Path(path).name}, {count}, scored on {truth}"


def describe_settings(config: Mapping[str, object]) -> list[tuple[str, str]]:
    """The run's settings (the parsed command line, ``vars(args)``) as ``(option, value)``
    rows in their order: ``--name`` and its value in words (:func:`describe_value`; one left
    out says what that means, :data:`UNSET`), a row "real log" describing each log scored
    (``config["logs"]``, :func:`describe_log`); callables and :data:`HIDDEN` entries left out."""
    rows = []
    for key, value in config.items():
        if key in HIDDEN or callable(value):
            continue
        if value is None:
            text = f"not given ({UNSET[key]})" if key in UNSET else "not given"
        else:
            text = describe_value(value)
        rows.append((f"--{key.replace('_', '-')}", text))
    if "logs" in config:
        logs = config["logs"]
        described = [describe_log(log) for log in logs] if isinstance(logs, Sequence) else []
        rows.append(("real log scored", "; ".join(described) or "none"))
    return rows
