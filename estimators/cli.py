"""``duallidar``: one command for every job, each a subcommand with its own ``--help``.

    duallidar run intel.clf.bz2 --truth intel-corrected.log.gz --estimators lidar_odometry slam
    duallidar leaderboard --worlds hallway --traces straight --seeds 0
    duallidar calibrate --world hallway --trace zigzag
    duallidar drive --drivers scripted --episodes 5
    duallidar train --timesteps 100000
    duallidar imitate --iterations 2

Subcommands are ``"module:function"`` strings imported when used (as
:mod:`estimators.registry` names its estimators), so ``duallidar --help`` stays fast and this
module imports neither the agents nor torch; each function takes ``(argv, prog)``. Built on
argparse: the standard library, no dependency to install.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

#: subcommand -> ("module:function", one-line summary), in the order ``--help`` lists them.
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "run": ("estimators.leaderboard.run_cli:main",
            "run estimators over your own CARMEN log or ROS bag and score them on its truth"),
    "leaderboard": ("estimators.leaderboard.cli:main",
                    "rank every estimator on the simulated scenarios and a real log "
                    "(also duallidar-leaderboard)"),
    "calibrate": ("estimators.calibration.__main__:main",
                  "estimate the Lidar mounts of a drive, a bag or CARMEN logs"),
    "drive": ("agents.evaluate:main",
              "score drivers on trace seeds (python -m agents.evaluate)"),
    "train": ("agents.train:main", "train a PPO driver from scratch (python -m agents.train)"),
    "imitate": ("agents.imitate:main",
                "train the learned driver by imitating the scan-aware expert "
                "(python -m agents.imitate)"),
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="duallidar", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="A car with planar Lidars in a pymunk world, Lidar-only motion estimators "
                    "and drivers. Each command has its own --help.",
        epilog="commands:\n" + "\n".join(f"  {name:12s} {summary}"
                                        for name, (_, summary) in SUBCOMMANDS.items()))
    parser.add_argument("--version", action="store_true", help="print the version and exit")
    parser.add_argument("command", nargs="?", choices=list(SUBCOMMANDS), metavar="COMMAND",
                        help=f"one of {', '.join(SUBCOMMANDS)}")
    parser.add_argument("arguments", nargs=argparse.REMAINDER, metavar="...",
                        help="the command's own options (duallidar COMMAND --help)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``duallidar COMMAND ...``; returns the command's exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    if argv and argv[0] in SUBCOMMANDS:  # the command's own parser reads the rest (--help too)
        command, rest = argv[0], argv[1:]
    else:
        args = parser.parse_args(argv)
        if args.version:
            from importlib.metadata import version

            print(f"duallidar {version('duallidar')}")
            return 0
        if args.command is None:
            parser.print_help()
            return 2
        command, rest = args.command, args.arguments
    module_name, function_name = SUBCOMMANDS[command][0].split(":")
    function = getattr(importlib.import_module(module_name), function_name)
    return int(function(rest, prog=f"duallidar {command}") or 0)


if __name__ == "__main__":
    sys.exit(main())
