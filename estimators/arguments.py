"""Value types for the command lines' ``argparse`` options: each turns a string into a checked
number or raises ``argparse.ArgumentTypeError``, which argparse prints as a one-line error
naming the option (exit status 2)."""

from __future__ import annotations

import argparse
import math

#: Seeds are NumPy's 32-bit unsigned range (what ``env.reset(seed=...)`` accepts).
MAX_SEED = 2**32 - 1


def _integer(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (a count of episodes, scans, steps, envs)."""
    return _integer(text, 1, "an integer >= 1")


def non_negative_int(text: str) -> int:
    """An integer >= 0."""
    return _integer(text, 0, "an integer >= 0")


def seed(text: str) -> int:
    """A seed in 0 .. 2**32 - 1."""
    value = _integer(text, 0, f"a seed in 0 .. {MAX_SEED}")
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed in 0 .. {MAX_SEED}, got {value}")
    return value


def _real(text: str, strict: bool) -> float:
    what = "a finite number > 0" if strict else "a finite number >= 0"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not math.isfinite(value) or value < 0 or (strict and value == 0):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0 (a resolution [m], a window [s])."""
    return _real(text, strict=True)


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (a tolerance [s])."""
    return _real(text, strict=False)
