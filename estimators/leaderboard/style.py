"""One look for every leaderboard figure: a fixed colour and marker per estimator name
(:data:`ESTIMATOR_STYLES`, so ``slam`` is the same colour in every figure of every run whatever
else was selected), a deterministic colour for any other name that differs from all the fixed
ones (:func:`estimator_style`), the truth in black on top (:data:`TRUTH`), obstacles in a light
fill no estimator colour resembles (:data:`OBSTACLE_FILL`), and one way to save a figure
(:func:`save_figure`: a PNG at :data:`DPI` and an SVG copy).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Resolution [dots per inch] of every PNG the leaderboard writes.
DPI = 200


@dataclass(frozen=True)
class Style:
    """How one estimator is drawn: a colour (``#rrggbb``) and a matplotlib marker."""

    colour: str
    marker: str


#: The registered estimators' styles: saturated, mutually distinct colours (Tableau 10 with its
#: grey, which looked like the walls, replaced by a dark indigo) and a marker each.
ESTIMATOR_STYLES: dict[str, Style] = {
    "pc": Style("#1f77b4", "o"),
    "pc_offset": Style("#ff7f0e", "s"),
    "pc_pg": Style("#2ca02c", "^"),
    "pc_rot": Style("#d62728", "v"),
    "pc_rot_icp": Style("#9467bd", "D"),
    "pc_fusion": Style("#8c564b", "P"),
    "icp": Style("#e377c2", "X"),
    "lidar_odometry": Style("#393b79", "*"),
    "slam": Style("#bcbd22", "h"),
    "zero": Style("#17becf", "<"),
}

#: The ground truth: black, drawn last (on top of every estimate).
TRUTH = Style("#000000", "")
#: Line width [pt] of the truth and of the estimates.
TRUTH_WIDTH = 2.4
ESTIMATE_WIDTH = 1.3
#: Obstacles: a light warm fill, far (CIE76 > :data:`MIN_DELTA_E`) from every estimator colour.
OBSTACLE_FILL = "#e6dcc8"
#: Smallest colour difference (CIE76 ΔE in L*a*b*) a generated colour keeps from every fixed
#: colour, the truth and the obstacle fill.
MIN_DELTA_E = 25.0
_MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*", "h", "<", ">", "p", "d")


def _to_rgb(colour: str) -> NDArray[np.float64]:
    text = colour.lstrip("#")
    return np.array([int(text[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])


def to_lab(colour: str) -> NDArray[np.float64]:
    """CIE L*a*b* (D65) of an ``#rrggbb`` sRGB colour."""
    rgb = _to_rgb(colour)
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722],
                    [0.0193, 0.1192, 0.9505]]) @ linear / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def delta_e(first: str, second: str) -> float:
    """CIE76 colour difference between two ``#rrggbb`` colours (about 2.3 = just noticeable)."""
    return float(np.linalg.norm(to_lab(first) - to_lab(second)))


@lru_cache(maxsize=1)
def extra_colours() -> tuple[str, ...]:
    """The colours a name outside :data:`ESTIMATOR_STYLES` may get: hues every 10 degrees at
    two brightness levels, kept when at least :data:`MIN_DELTA_E` from every fixed colour, the
    truth and the obstacle fill."""
    import colorsys

    taken = [s.colour for s in ESTIMATOR_STYLES.values()] + [TRUTH.colour, OBSTACLE_FILL]
    candidates = []
    for value, saturation in ((0.55, 0.9), (0.85, 0.75)):
        for hue in range(0, 360, 10):
            r, g, b = colorsys.hsv_to_rgb(hue / 360, saturation, value)
            colour = f"#{round(255 * r):02x}{round(255 * g):02x}{round(255 * b):02x}"
            if all(delta_e(colour, other) >= MIN_DELTA_E for other in taken):
                candidates.append(colour)
    return tuple(candidates)


def estimator_style(name: str) -> Style:
    """The style of estimator ``name``: its entry of :data:`ESTIMATOR_STYLES`, else one of
    :func:`extra_colours` and a marker chosen by a hash of the name (the same in every run and
    every subset; two new names may share a colour, rarely also the marker)."""
    if name in ESTIMATOR_STYLES:
        return ESTIMATOR_STYLES[name]
    digest = int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "big")
    colours = extra_colours()
    return Style(colours[digest % len(colours)], _MARKERS[(digest // len(colours)) % len(_MARKERS)])


def obstacle_colormap() -> Any:
    """A two-colour matplotlib colour map: white free space, :data:`OBSTACLE_FILL` obstacles."""
    from matplotlib.colors import ListedColormap

    return ListedColormap(["#ffffff", OBSTACLE_FILL])


def figure_title(figure: Any, text: str) -> None:
    """The figure's title, left-aligned and wrapped to its width (so that it never runs into
    a legend in the right margin)."""
    import textwrap

    width = max(40, int(figure.get_figwidth() * 9))  # about 9 characters per inch at 12 pt
    figure.suptitle("\n".join(textwrap.wrap(text, width)), x=0.01, ha="left")


def save_figure(figure: Any, path: Path) -> list[Path]:
    """Save a matplotlib figure as ``path`` (PNG at :data:`DPI`) and as its SVG copy beside it;
    returns both paths. A figure with constrained layout (every leaderboard figure: its layout
    keeps a legend placed outside the axes) is saved as laid out, else with a tight bounding
    box (one more draw)."""
    path = Path(path)
    vector = path.with_suffix(".svg")
    tight = None if figure.get_layout_engine() is not None else "tight"
    figure.savefig(path, dpi=DPI, bbox_inches=tight)
    figure.savefig(vector, bbox_inches=tight)
    return [path, vector]
