"""A job's worker processes die with it: ``SIGKILL`` on the main process of a job leaves no process
of the job behind (``quadest.app.parent_watch``; docs/usage.md, "Stopping a job")."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads /proc")

QUADEST = str(Path(sys.executable).with_name("quadest"))


def _stat(pid: str) -> tuple[str, int, int, int] | None:
    """(state, process group, parent, CPU ticks) of process ``pid``, or None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()  # after "pid (comm) "
    return fields[0], int(fields[2]), int(fields[1]), int(fields[11]) + int(fields[12])


def _group(pgid: int) -> dict[int, tuple[str, int, int, int]]:
    """The live (not zombie) processes of process group ``pgid``."""
    found = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            stat = _stat(entry)
            if stat is not None and stat[1] == pgid and stat[0] != "Z":
                found[int(entry)] = stat
    return found


def _wait(condition, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.2)
    return condition()


def _kill_main_and_expect_nothing_left(job: subprocess.Popen) -> None:
    """SIGKILL the job's main process; within 10 s no process of its group may be left."""
    job.send_signal(signal.SIGKILL)
    job.wait()
    assert _wait(lambda: not _group(job.pid), 10), f"processes left: {_group(job.pid)}"


def _kill_group(job: subprocess.Popen) -> None:
    """Whatever the test's outcome, leave no process of the job's group behind."""
    try:
        os.killpg(job.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@pytest.mark.slow
def test_killing_a_job_kills_its_estimator_workers(tmp_path):
    env = {**os.environ, "QUADEST_CACHE_DIR": str(tmp_path / "cache")}
    args = [QUADEST, "estimator=[ekf,ukf]", "workers=2", "runs=10", "duration=60", "progress=false",
            "cache.enabled=false", "output.figures=false", f"hydra.run.dir={tmp_path / 'out'}"]  # fmt: skip
    job = subprocess.Popen(args, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    tick = os.sysconf("SC_CLK_TCK")
    try:
        # the two estimator workers, each past its start (imports, the pool's initializer) and running
        def working() -> bool:
            workers = [s for pid, s in _group(job.pid).items() if s[2] == job.pid and "spawn_main" in _cmdline(pid)]
            return len(workers) == 2 and all(s[3] >= 3 * tick for s in workers)

        assert _wait(working, 300), f"the job's workers did not start: {job.stderr.read().decode()[-2000:]}"
        _kill_main_and_expect_nothing_left(job)
    finally:
        _kill_group(job)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


LAUNCHER = """
import multiprocessing, sys, time
from quadest.app.parent_watch import _pdeathsig, watch_parent

def cell():
    if sys.argv[1] == "kernel":
        assert _pdeathsig()  # the kernel's signal alone, no polling thread
    else:
        watch_parent()  # what quadest.app.cli does first in a launcher's worker
    print("watching", flush=True)
    time.sleep(300)

if __name__ == "__main__":
    multiprocessing.get_context("spawn").Process(target=cell).start()
    time.sleep(300)
"""


@pytest.mark.parametrize("how", ["poll", "kernel"])
def test_a_launchers_worker_dies_with_the_sweeps_main_process(tmp_path, how):
    """A Hydra launcher's worker (joblib's loky, like multiprocessing, records its parent) watches
    the process that started it; on Linux the kernel's parent-death signal alone suffices too."""
    if how == "kernel" and not sys.platform.startswith("linux"):
        pytest.skip("PR_SET_PDEATHSIG is Linux's")
    script = tmp_path / "launcher.py"
    script.write_text(LAUNCHER)
    command = [sys.executable, str(script), how]
    main = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, text=True)
    try:
        assert main.stdout.readline().strip() == "watching"
        assert len(_group(main.pid)) >= 2
        main.send_signal(signal.SIGKILL)
        main.wait()
        assert _wait(lambda: not _group(main.pid), 10), f"processes left: {_group(main.pid)}"
    finally:
        try:
            os.killpg(main.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_killing_a_joblib_sweep_kills_its_launchers_workers(tmp_path):
    """The real launcher path: ``quadest -m hydra/launcher=quadest_joblib`` killed while both of
    its cells run leaves no loky worker behind (each cell's job calls ``watch_parent`` first)."""
    sweep = tmp_path / "sweep"
    env = {**os.environ, "QUADEST_CACHE_DIR": str(tmp_path / "cache")}
    args = [QUADEST, "-m", "hydra/launcher=quadest_joblib", "model=linear", "estimator=[ekf]", "runs=200",
            "duration=120,121", "progress=false", "cache.enabled=false", "output.figures=false",
            f"hydra.sweep.dir={sweep}"]  # fmt: skip
    job = subprocess.Popen(args, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        # both cells started: Hydra writes a cell's .hydra folder just before it calls the job
        def started() -> bool:
            workers = [pid for pid in _group(job.pid) if "popen_loky_posix" in _cmdline(pid)]
            return len(workers) == 2 and all((sweep / cell / ".hydra" / "overrides.yaml").is_file() for cell in "01")

        assert _wait(started, 300), f"the sweep's cells did not start: {job.stderr.read().decode()[-2000:]}"
        time.sleep(2.0)  # past the job's first statement (watch_parent)
        _kill_main_and_expect_nothing_left(job)
    finally:
        _kill_group(job)
