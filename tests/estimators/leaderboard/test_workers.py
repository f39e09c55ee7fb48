"""The leaderboard's processes under faults: workers die with a killed
parent, Ctrl-C prints one line and exits 130 with the finished scenarios kept, and a bad
``--seeds`` is refused before anything runs."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from estimators import leaderboard
from estimators.leaderboard.database import ExperimentDatabase

ROOT = Path(__file__).resolve().parents[3]


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(")")[-1].split()[0] != "Z"  # a zombie is dead
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_die_when_the_parent_is_killed(tmp_path):
    script = textwrap.dedent("""
        import os, sys, time
        from estimators.leaderboard.workers import process_pool
        pool = process_pool(2)
        pids = {pool.submit(os.getpid).result() for _ in range(8)}
        while len(pids) < 2:
            pids.add(pool.submit(os.getpid).result())
        futures = [pool.submit(time.sleep, 600) for _ in range(2)]
        print(" ".join(map(str, sorted(pids))), flush=True)
        time.sleep(600)
    """)
    parent = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdout=subprocess.PIPE,
                              text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    workers = [int(pid) for pid in parent.stdout.readline().split()]
    assert len(workers) == 2 and all(alive(pid) for pid in workers)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10.0
    while any(alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(pid) for pid in workers)
    parent.stdout.close()


@pytest.mark.slow
@pytest.mark.parametrize("workers", ["1", "2"])
def test_ctrl_c_prints_one_line_exits_130_and_keeps_finished_scenarios(tmp_path, workers):
    out = tmp_path / "out"
    argv = ["--worlds", "hallway", "--traces", "straight", "--seeds", *map(str, range(12)),
            "--estimators", "zero", "--workers", workers, "--no-real", "--no-progress",
            "--out", str(out)]
    run = subprocess.Popen([sys.executable, "-m", "estimators.leaderboard", *argv], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)},
                           start_new_session=True,  # its own process group, as a terminal's
                           # A shell runs background jobs with SIGINT ignored, and Python keeps an
                           # inherited SIG_IGN: give the run the terminal's default, as Ctrl-C
                           # would find it.
                           preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    db_path = out / "experiments.sqlite"
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and run.poll() is None:
        time.sleep(0.5)
        if db_path.exists():
            with ExperimentDatabase(db_path) as db:
                if db.counts()["sensor_datasets"] >= 1:
                    break
    assert run.poll() is None, "the run finished before it could be interrupted"
    os.killpg(run.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    _, err = run.communicate(timeout=60)
    assert run.returncode == 130
    assert "Traceback" not in err
    # the env's one-time note when its kernels are not cached yet is no part of the interruption
    lines = [line for line in err.splitlines()
             if line.strip() and "compiles the simulator's numba kernels" not in line]
    assert len(lines) == 1 and lines[0].startswith("interrupted; ")
    assert lines[0].endswith(" scenarios stored; re-run to resume")
    stored = int(lines[0].split()[1])
    # the message never counts more than the database keeps; a scenario committed in the
    # instant before Ctrl-C may be kept but not yet counted
    with ExperimentDatabase(db_path) as db:
        assert db.counts()["sensor_datasets"] >= max(stored, 1)


@pytest.mark.parametrize("seeds", [["-1"], ["0", "4294967296"]])
def test_bad_seeds_are_refused_up_front(tmp_path, seeds, capsys):
    with pytest.raises(SystemExit) as exit_info:
        leaderboard.main(["--seeds", *seeds, "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    assert "--seeds: expected integers in 0 .. 2**32 - 1" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
