"""The leaderboard's local worker processes: they die with the parent and leave Ctrl-C to it.

A worker of a plain ``ProcessPoolExecutor`` outlives a parent killed with SIGKILL (it keeps
computing for minutes and holds the parent's output pipes), and on Ctrl-C every worker of the
terminal's process group prints its own ``KeyboardInterrupt`` traceback. So each worker:

* asks Linux to send it SIGKILL when its parent dies (``prctl(PR_SET_PDEATHSIG)``, via
  ctypes; elsewhere a daemon thread polls the parent's pid every second instead), and exits at
  once if the parent is already gone when it starts;
* ignores SIGINT: the parent handles Ctrl-C, commits what is finished and stops the workers
  once their tasks in flight are done (:func:`stop_workers`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor

#: ``PR_SET_PDEATHSIG`` from ``<sys/prctl.h>``.
PR_SET_PDEATHSIG = 1
#: [s] how often a worker without prctl checks that its parent is alive.
PARENT_POLL_INTERVAL = 1.0
#: [s] how long the tasks in flight get to finish after Ctrl-C before their workers are killed.
FINISH_SECONDS = 30.0


def process_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes that die with this process and ignore Ctrl-C."""
    return ProcessPoolExecutor(workers, initializer=init_worker, initargs=(os.getpid(),))


def init_worker(parent_pid: int) -> None:
    """Worker initializer: die with ``parent_pid``, ignore SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if not _set_parent_death_signal():
        threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True).start()
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


def _set_parent_death_signal() -> bool:
    """Linux: SIGKILL this process when its parent dies; False where that is unavailable."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent_pid: int) -> None:
    while os.getppid() == parent_pid:
        time.sleep(PARENT_POLL_INTERVAL)
    os._exit(1)


def stop_workers(executor: object) -> None:
    """Cancel what is queued on a process pool and stop its workers (after Ctrl-C): the tasks
    in flight finish (not committed: a re-run redoes them) and the workers exit; one still
    busy after :data:`FINISH_SECONDS` is killed. Killed at once, a worker can die halfway
    through writing its result, and the pool's reader thread then waits for the rest of it
    for ever, holding the process open after it printed that it was interrupted."""
    if not isinstance(executor, ProcessPoolExecutor):
        return
    processes = list((getattr(executor, "_processes", None) or {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + FINISH_SECONDS
    for process in processes:
        process.join(timeout=max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.kill()
            process.join(timeout=5.0)
