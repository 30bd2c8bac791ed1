"""Worker processes that die with the process that started them.

A job's estimator workers (:mod:`quadest.app.estimator_runs`) and the Hydra joblib launcher's
workers (one sweep cell each) wait on a pipe from their parent; if the parent is killed
(``SIGKILL``, an out-of-memory kill, a cluster's time limit) nothing tells them, and they would
linger for minutes holding their memory. Each worker therefore watches its parent:

- on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (``man 2 prctl``) has the kernel kill it when the
  thread that started it ends; used only where that thread is its parent's main thread (a pool
  created from another thread could outlive it);
- everywhere, a daemon thread polls ``os.getppid()`` every :data:`POLL_SECONDS` and kills the
  process once its parent is gone (the process is then adopted, so its parent id changes).

A worker killed this way takes its own workers with it, since they watch it in turn.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time

POLL_SECONDS = 0.5
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _kill_self() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _pdeathsig() -> bool:
    """Ask the Linux kernel for ``SIGKILL`` when the parent thread ends; whether it was set."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)  # the process's own symbols, libc's among them
        return libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _poll(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(POLL_SECONDS)
    _kill_self()


def die_with_parent(parent: int, kernel_signal: bool = False) -> None:
    """Kill this process when process ``parent`` (its parent) ends: with ``kernel_signal`` also by
    ``PR_SET_PDEATHSIG`` (module docstring), always by a polling thread. A pool's initializer."""
    if kernel_signal:
        _pdeathsig()
    if os.getppid() != parent:  # the parent died before the watch began
        _kill_self()
    threading.Thread(target=_poll, args=(parent,), name="quadest-parent-watch", daemon=True).start()


def watch_parent() -> None:
    """In a process started by :mod:`multiprocessing` or loky (a launcher's or a pool's worker),
    :func:`die_with_parent` of the process that started it; in a main process, nothing (a job
    run from a shell outlives the shell, as any command does). Idempotent."""
    parent = multiprocessing.parent_process()
    if parent is None or any(t.name == "quadest-parent-watch" for t in threading.enumerate()):
        return
    die_with_parent(parent.pid)


def pool_options() -> dict:
    """The ``initializer`` and ``initargs`` of a worker pool created by this process: each worker
    dies with it, by the kernel's signal too when this is the main thread."""
    in_main_thread = threading.current_thread() is threading.main_thread()
    return {"initializer": die_with_parent, "initargs": (os.getpid(), in_main_thread)}
