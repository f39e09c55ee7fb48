"""The leaderboard's figure style and plots: fixed colours per estimator name whatever the
selection, distinct colours for new names, figures written at the stated dpi with a vector
copy, traces clipped at the world's edge, and the KITTI-style segment error."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from estimators.leaderboard.style import (
    DPI,
    ESTIMATOR_STYLES,
    MIN_DELTA_E,
    OBSTACLE_FILL,
    TRUTH,
    delta_e,
    estimator_style,
)
from estimators.leaderboard.trace_drawing import clip_to_bounds
from estimators.registry import names

pytest.importorskip("matplotlib")


def board_row(name: str, ms: float, ate: float) -> dict[str, float | str]:
    return {"estimator": name, "ms_per_step": ms, "ms_per_step_std": 0.1, "ate_rmse_m": ate,
            "ate_rmse_m_std": 0.01, "accuracy_percent": 90.0, "accuracy_percent_std": 1.0}


def test_every_registered_estimator_has_its_own_fixed_style() -> None:
    assert set(names()) <= set(ESTIMATOR_STYLES)
    colours = [s.colour for s in ESTIMATOR_STYLES.values()]
    assert len(set(colours)) == len(colours)
    assert len({s.marker for s in ESTIMATOR_STYLES.values()}) == len(colours)
    for first, second in itertools.combinations(colours, 2):
        assert delta_e(first, second) > 20, (first, second)
    for colour in colours:  # none looks like the truth or the obstacles
        assert delta_e(colour, TRUTH.colour) > 40 and delta_e(colour, OBSTACLE_FILL) > 40


def test_new_names_get_deterministic_colours_unlike_every_fixed_one() -> None:
    taken = [s.colour for s in ESTIMATOR_STYLES.values()] + [TRUTH.colour, OBSTACLE_FILL]
    for name in ("my_estimator", "kiss_icp", "x" * 40, "pc_fusion_v2"):
        style = estimator_style(name)
        assert style == estimator_style(name)
        assert min(delta_e(style.colour, other) for other in taken) >= MIN_DELTA_E
    assert delta_e("#000000", "#ffffff") == pytest.approx(100.0, abs=0.1)  # L* 0 -> 100


def test_an_estimator_keeps_its_colour_across_runs_with_other_estimators(tmp_path: Path) -> None:
    from PIL import Image

    from estimators.leaderboard.plots import draw_speed_accuracy

    runs = {"a": [board_row("slam", 4.0, 0.02), board_row("pc", 1.0, 9.0)],
            "b": [board_row("icp", 2.0, 1.5), board_row("zero", 0.01, 16.0),
                  board_row("new_method", 3.0, 0.5), board_row("slam", 4.1, 0.03)]}
    for run, rows in runs.items():
        (tmp_path / run).mkdir()
        png, svg = draw_speed_accuracy(rows, tmp_path / run)
        assert png.suffix == ".png" and svg.suffix == ".svg" and svg.stat().st_size > 1000
        with Image.open(png) as image:
            assert min(image.info["dpi"]) == pytest.approx(DPI, abs=0.5) and DPI >= 150
            pixels = np.asarray(image.convert("RGB"))
        assert pixels.std() > 0
        drawn = svg.read_text()
        for row in rows:  # each estimator's marker is filled with its fixed colour
            assert estimator_style(str(row["estimator"])).colour in drawn, (run, row)
        # and the PNG holds pixels of that colour
        slam = np.array([int(ESTIMATOR_STYLES["slam"].colour[i:i + 2], 16) for i in (1, 3, 5)])
        assert np.any(np.all(np.abs(pixels.astype(int) - slam) <= 2, axis=-1)), run
    assert ESTIMATOR_STYLES["pc"].colour not in (tmp_path / "b" / "speed_accuracy.svg").read_text()


def test_a_trace_leaving_the_world_is_cut_with_an_exit_at_the_last_inside_point() -> None:
    points = np.array([[1.0, 1.0], [2.0, 1.0], [3.5, 1.0], [2.5, 1.0], [1.0, 2.5]])
    clipped, exits = clip_to_bounds(points, (0.0, 0.0, 3.0, 2.0))
    assert np.isnan(clipped[2]).all() and np.isnan(clipped[4]).all()
    np.testing.assert_array_equal(clipped[[0, 1, 3]], points[[0, 1, 3]])
    assert len(exits) == 2
    np.testing.assert_array_equal(exits[0][0], [2.0, 1.0])
    assert exits[0][1] == pytest.approx(0.0)  # leaving along +x
    assert exits[1][1] == pytest.approx(math.atan2(1.5, -1.5))


def test_segment_errors_against_a_closed_form_drift() -> None:
    from estimators.leaderboard.plots import segment_errors

    x = np.arange(0.0, 30.0, 0.1)
    truth = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    exact = segment_errors(truth, truth)
    assert sorted(exact) == [1.0, 2.0, 5.0, 10.0, 20.0]
    assert all(np.allclose(moved, 0) and np.allclose(turned, 0)
               for moved, turned in exact.values())
    stretched = truth * np.array([1.1, 1.0, 1.0])  # 10 % too far along every segment
    for length, (moved, _) in segment_errors(stretched, truth).items():
        assert np.allclose(moved, 10.0 * np.ceil(length / 0.1 - 1e-9) * 0.1 / length, rtol=0.02)
    short = segment_errors(truth[:50], truth[:50])  # 4.9 m: no 5 m segment fits
    assert sorted(short) == [1.0, 2.0]


def test_the_lidar_image_is_cropped_to_the_scans_extent_and_the_sensor() -> None:
    from estimators.leaderboard.figures import scan_extent
    from estimators.paper.scan_image import scan_to_image

    angles = np.linspace(-np.pi / 4, np.pi / 4, 91)  # a wall 3 m ahead, seen over +-45 deg
    ranges = 3.0 / np.cos(angles)
    image = scan_to_image(ranges, angles, 10.0)
    xmin, xmax, ymin, ymax = scan_extent(image, 0.05, margin=0.5)
    assert xmin == pytest.approx(-0.5) and xmax == pytest.approx(3.05 + 0.5, abs=0.06)
    assert ymin == pytest.approx(-3.5, abs=0.06) and ymax == pytest.approx(3.5, abs=0.06)
    assert xmax - xmin < 5 and ymax - ymin < 8  # not the image's 20 m x 20 m
    assert scan_extent(np.zeros((400, 400)), 0.05) == (-10.0, 10.0, -10.0, 10.0)


def test_the_lead_figure_zooms_on_the_drive_at_the_panels_shape() -> None:
    from estimators.leaderboard.figures import drive_extent, with_aspect

    truth = np.array([[10.0, 20.0, 0.0], [30.0, 22.0, 0.0]])
    lost = np.array([[10.0, 20.0, 0.0], [80.0, 22.0, 0.0]])  # leaves the 40 m world
    box = drive_extent(truth, [lost, np.full((2, 3), np.nan)], (0.0, 0.0, 40.0, 40.0))
    assert box == pytest.approx((7.0, 17.0, 43.0, 25.0))  # cut at x = 40, 3 m margin
    xmin, ymin, xmax, ymax = with_aspect(box, 0.5)
    assert (ymax - ymin) / (xmax - xmin) == pytest.approx(0.5)
    assert (xmin, xmax) == pytest.approx((7.0, 43.0))  # only the short side grows
    assert (ymin + ymax) / 2 == pytest.approx(21.0)
    tall = with_aspect((0.0, 0.0, 1.0, 4.0), 0.5)
    assert tall == pytest.approx((-3.5, 0.0, 4.5, 4.0))
