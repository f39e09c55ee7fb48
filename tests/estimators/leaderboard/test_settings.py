"""The run's configuration in the report: option names as typed, values in words, no Python
reprs and no bare None."""

from __future__ import annotations

import argparse
from pathlib import Path

from estimators.leaderboard.real_logs import RealLog
from estimators.leaderboard.settings import describe_settings, describe_value


def test_settings_read_as_options_and_values_in_words() -> None:
    aces = RealLog("aces", "/data/radish/aces.clf.bz2", "/data/radish/aces.relations", 1000)
    bag = RealLog("intel", "/logs/intel.bag", None, None, "/ground_truth")
    args = argparse.Namespace(worlds=None, traces=["zigzag", "right_turn"], seeds=[0, 1],
                              moving_obstacles=False, noise=0.01, db=None,
                              out=Path("leaderboard"), real_scans=None, tum=True,
                              argv=["--seeds", "0", "1"], logs=[aces, bag], func=print)
    rows = dict(describe_settings(vars(args)))
    assert rows["--worlds"].startswith("not given (the default matrix")
    assert rows["--traces"] == "zigzag, right_turn" and rows["--seeds"] == "0, 1"
    assert rows["--moving-obstacles"] == "no" and rows["--tum"] == "yes"
    assert rows["--noise"] == "0.01" and rows["--out"] == "leaderboard"
    assert rows["--db"] == "not given (experiments.sqlite in the output directory)"
    assert rows["real log scored"] == (
        "ACES: aces.clf.bz2, first 1,000 scans, scored on relations aces.relations; "
        "INTEL: intel.bag, all scans, scored on ground-truth topic /ground_truth")
    assert "--argv" not in rows and "--logs" not in rows and "--func" not in rows
    text = " ".join(value for pair in rows.items() for value in pair)
    assert "None" not in text and "RealLog(" not in text and "[" not in text


def test_values_in_words() -> None:
    assert describe_value(None) == "not given"
    assert describe_value([]) == "none" and describe_value((1.5, 2.0)) == "1.5, 2"
    assert describe_value(True) == "yes" and describe_value("tcp://host:8786") == "tcp://host:8786"
