"""``python -m estimators.leaderboard``: the leaderboard's command line (:func:`cli.main`)."""

import sys

from estimators.leaderboard.cli import main

sys.exit(main())
