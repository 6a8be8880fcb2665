"""Worker processes that never outlive their parent nor hold its output open.

A ``dracc analyze`` or ``dracc fleet`` killed by SIGKILL (or the OOM killer) cannot stop
its pool: its workers would live on (PPID 1, their memory held) and keep the caller's
pipes open, so cron waiting for the end of dracc's output would hang.  Every pool of
dracc starts its workers with :func:`detach_worker`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time

#: seconds between the watchdog's looks at a worker's parent
WATCHDOG_S = 0.5


def die_with_parent(parent_pid: int | None) -> None:
    """End this process when ``parent_pid`` (its parent at start) is gone: at once where
    ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` exists (Linux), else within ``WATCHDOG_S``."""
    ppid = os.getppid() if parent_pid is None else parent_pid
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
        except (OSError, AttributeError, TypeError):  # pragma: no cover - no prctl
            pass
    if os.getppid() != ppid:  # the parent died before the death signal was set
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(WATCHDOG_S)
            if os.getppid() != ppid:
                os._exit(1)

    threading.Thread(target=watch, name="dracc-parent-watchdog", daemon=True).start()


def detach_worker(parent_pid: int | None) -> None:
    """A pool initializer: die with the parent, and point stdin, stdout and stderr at
    /dev/null (results and errors go back through the pool)."""
    die_with_parent(parent_pid)
    try:
        null = os.open(os.devnull, os.O_RDWR)
        for fd in (0, 1, 2):
            os.dup2(null, fd)
        if null > 2:
            os.close(null)
    except OSError:  # pragma: no cover - no /dev/null
        pass
