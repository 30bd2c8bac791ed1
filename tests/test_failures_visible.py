"""Failures a user can see: every configuration that cannot run is refused before any work with one
line naming the key (docs/usage.md, "Refused before any work"); a request too large for the
machine is refused or warned about; a log cut short is named; a sweep with a failed cell exits
non-zero; the paired summary says when its test cannot reach significance."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from helpers import compose_config
from quadest.app import sizing
from quadest.app.cli import failure_note, precheck
from quadest.app.job import run_job
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.estimators.params import smallest_alpha, unscented_constraints
from quadest.evaluation.paired import SIGNIFICANCE, runs_to_reach, smallest_wilcoxon_p, summary_lines
from quadest.numerics.sigma_points import ut_weights
from quadest.replay.data import shipped_log
from quadest.replay.ulog import incomplete_tail

ROOT = Path(__file__).resolve().parents[1]


def refused(capsys, args: list[str]) -> str:
    """The one line ``precheck`` ends ``args`` with (exit code 2)."""
    with pytest.raises(SystemExit) as done:
        precheck(args)
    assert done.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("quadest: error: "), lines
    return lines[0]


@pytest.mark.parametrize(
    ("args", "key", "says"),
    [
        (["estimator.srukf.alpha=1e-10"], "estimator.srukf.alpha=1e-10", "too small"),
        (["estimator.srukf.alpha=1e-300"], "estimator.srukf.alpha=1e-300", "too small"),
        (["estimator.ukf.alpha=1e-10"], "estimator.ukf.alpha=1e-10", "too small"),
        (["sensor.accel.white_noise=inf"], "sensor.accel.white_noise=inf", "inf is not a finite number"),
        (["sensor.gyro.bias=nan"], "sensor.gyro.bias=nan", "nan is not a finite number"),
        (["model.process_noise.velocity=-inf"], "model.process_noise.velocity", "not a finite number"),
        (["duration=inf"], "duration=inf", "not a finite number"),
        (["estimator=[srukf,srukf]"], "estimator=", "srukf selected twice"),
        (["estimator=[ekf,ukf,ekf]"], "estimator=", "ekf selected twice"),
        (["experiment=px4_replay", "source.warmup=100"], "source.warmup=100.0", "less than the"),
    ],
)
def test_a_configuration_that_cannot_run_is_refused_naming_its_key(capsys, args, key, says):
    line = refused(capsys, args)
    assert f"quadest: error: {key}" in line and says in line


def test_alpha_too_small_names_alpha_not_kappa(capsys):
    line = refused(capsys, ["estimator.srukf.alpha=1e-300"])
    assert "kappa=" not in line.split("is invalid")[0]


@pytest.mark.parametrize("n", [1, 2, 3, 6, 9, 12, 15, 16, 21])
@pytest.mark.parametrize("kappa", [0.0, 3.0, -0.5, 1e3])
def test_the_validation_of_n_plus_lambda_agrees_with_the_filters_weights(n, kappa):
    """The check is the filter's own arithmetic: over alphas from 1e-300 to 1, a value passes the
    validation exactly when the UT's weights can be built; and the alpha the message offers works."""
    if not n + kappa > 0:
        pytest.skip("kappa itself is refused")
    for alpha in np.geomspace(1e-300, 1.0, 600):
        passes = not unscented_constraints({"alpha": float(alpha), "kappa": kappa}, n)
        try:
            ut_weights(n, float(alpha), 2.0, kappa)
            builds = True
        except ValueError:
            builds = False
        assert passes == builds, (alpha, n, kappa)
    offered = smallest_alpha(n, kappa)
    ut_weights(n, offered, 2.0, kappa)
    assert not unscented_constraints({"alpha": offered, "kappa": kappa}, n)


def test_an_output_folder_that_cannot_be_made_is_refused(capsys, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    line = refused(capsys, ["runs=2", "duration=0.5", f"hydra.run.dir={blocker / 'out'}"])
    assert "hydra.run.dir=" in line and "is not a folder" in line
    line = refused(capsys, ["-m", "runs=2,3", f"hydra.sweep.dir={blocker / 'sweep'}"])
    assert "hydra.sweep.dir=" in line and "is not a folder" in line


def test_an_output_folder_that_cannot_be_written_is_refused(capsys, tmp_path, monkeypatch):
    """A folder the user may not write into (mode 555 for anyone but root, a read-only mount) is
    refused with one line; the permission is simulated for that one folder, since root (CI
    containers) may write anywhere."""
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access

    def access(path, mode, **kw) -> bool:  # that folder's write bit denied, nothing else
        return not (Path(path) == locked and mode & os.W_OK) and real_access(path, mode, **kw)

    monkeypatch.setattr(os, "access", access)
    for args, key in ((["runs=2", "duration=0.5", f"hydra.run.dir={locked / 'out'}"], "hydra.run.dir="),
                      (["-m", "runs=2,3", f"hydra.sweep.dir={locked}"], "hydra.sweep.dir=")):  # fmt: skip
        line = refused(capsys, args)
        assert key in line and f"{locked} is not writable" in line


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_whose_file_system_takes_no_new_folder_is_refused(capsys):
    """Root's permissions allow writing into /proc, which takes no new folder: refused with one
    line naming the key before any work, not a traceback when Hydra creates the folder."""
    line = refused(capsys, ["runs=2", "duration=0.5", "hydra.run.dir=/proc/quadest_out"])
    assert "hydra.run.dir=" in line and "/proc takes no new folder" in line


def test_a_job_larger_than_the_machine_is_refused_naming_the_keys(capsys, monkeypatch):
    monkeypatch.setattr(sizing, "available_memory", lambda: 2**30)
    line = refused(capsys, ["runs=1000", "duration=100"])
    for key in ("runs", "duration", "sample_period"):
        assert key in line
    assert "GiB" in line


def test_a_job_near_the_machines_memory_is_warned_about(capsys, monkeypatch):
    """Between :data:`WARN_FRACTION` of the available memory and all of it: a warning, no refusal."""
    need = sizing.job_bytes(50, 2001, 6, 3, 2, 3)
    monkeypatch.setattr(sizing, "available_memory", lambda: int(need / (0.5 * (1 + sizing.WARN_FRACTION))))
    assert sizing.check_size(50, 20.0, 0.01, 6, 3, 2, 3) == need
    assert "quadest: warning: the job needs about" in capsys.readouterr().err


def test_a_job_one_byte_above_the_machines_memory_is_refused(monkeypatch):
    """The refusal's edge is the available memory itself: one byte short refuses, enough warns."""
    need = sizing.job_bytes(50, 2001, 6, 3, 2, 3)
    monkeypatch.setattr(sizing, "available_memory", lambda: need - 1)
    with pytest.raises(ConfigError, match=r"^runs=50 is invalid: the job needs about"):
        sizing.check_size(50, 20.0, 0.01, 6, 3, 2, 3)
    monkeypatch.setattr(sizing, "available_memory", lambda: need)
    assert sizing.check_size(50, 20.0, 0.01, 6, 3, 2, 3) == need


def test_the_size_estimate_counts_every_array_it_names():
    """Doubling runs doubles the data and state terms; the saved series follow saved_runs alone."""
    base = sizing.job_bytes(10, 101, 4, 2, 1, 3)
    assert sizing.job_bytes(20, 101, 4, 2, 1, 3) - base == 8 * 10 * 101 * 2 * 4 + 8 * 10 * 9 * 4
    assert sizing.job_bytes(10, 101, 4, 2, 1, 4) - base == 2 * 8 * 101 * 3 * 4
    assert sizing.job_bytes(10, 101, 4, 2, 2, 3) > base  # each worker process holds the data


def test_available_memory_is_what_the_kernel_reports():
    meminfo = Path("/proc/meminfo")
    if not meminfo.is_file():
        pytest.skip("no /proc/meminfo")
    field = next(line for line in meminfo.read_text().splitlines() if line.startswith("MemAvailable:"))
    reported = int(field.split()[1]) * 1024
    assert abs(sizing.available_memory() - reported) < 0.25 * reported  # the same figure, read moments apart


def test_a_truncated_log_is_named(tmp_path):
    """A log cut mid-message is found by its message headers; the shipped log ends on a boundary."""
    data = shipped_log().read_bytes()
    assert incomplete_tail(shipped_log()) == 0
    for cut in (len(data) // 2, len(data) // 3 + 1, len(data) - 1):
        path = tmp_path / f"cut{cut}.ulg"
        path.write_bytes(data[:cut])
        tail = incomplete_tail(path)
        assert 0 < tail <= cut or _on_boundary(data, cut)


def _on_boundary(data: bytes, cut: int) -> bool:
    offset = 16
    while offset < cut:
        offset += 3 + int.from_bytes(data[offset : offset + 2], "little")
    return offset == cut


def test_a_truncated_log_replays_with_a_warning(capsys, tmp_path):
    data = shipped_log().read_bytes()
    cut = len(data) // 2
    while _on_boundary(data, cut):
        cut += 1
    path = tmp_path / "cut.ulg"
    path.write_bytes(data[:cut])

    validate(compose_config(["experiment=px4_replay", f"source.path={path}", "duration=20"]))
    err = capsys.readouterr().err
    assert f"quadest: warning: {path} ends in" in err and "truncated" in err
    # the window replayed, not the whole truncated log
    assert "holds 34.076 s of IMU and attitude data, of which 20.000 s are replayed" in err


def test_an_estimator_labelled_px4_is_refused_in_a_replay():
    """``truth_errors.csv`` names PX4's own estimate ``px4``: an estimator of that label would share its rows."""
    overrides = ["experiment=px4_replay", "+estimator.px4.kind=mekf"]
    with pytest.raises(ConfigError, match=r"estimator\.px4='px4' is invalid: a label other than 'px4'"):
        validate(compose_config(overrides))


def test_a_log_shorter_than_the_duration_is_named(capsys):
    """The shipped log holds 68.874 s of IMU and attitude data (``source.warmup``'s refusal says so):
    asking for 100 s replays it to its end, with a warning naming the log and both lengths."""
    validate(compose_config(["experiment=px4_replay", "duration=100"]))
    err = capsys.readouterr().err
    assert f"quadest: warning: {shipped_log()} holds 68.874 s after source.start=0, less than duration=100" in err
    validate(compose_config(["experiment=px4_replay", "duration=60"]))
    assert "less than duration" not in capsys.readouterr().err


@pytest.mark.parametrize("n", range(2, 16))
def test_the_smallest_wilcoxon_p_is_scipys_exact_p_of_one_signed_sample(n):
    """Every difference of one sign is the most extreme sample of the signed-rank test."""
    assert smallest_wilcoxon_p(n) == pytest.approx(stats.wilcoxon(np.arange(1.0, n + 1)).pvalue, rel=1e-12)


def _paired_table(runs: int, states: int) -> pd.DataFrame:
    rows = [{"pair": "b - a", "state": f"s{j}", "runs": runs, "excluded_runs": 0, "rel_diff": 2.16,
             "rel_ci_low": 1.77, "rel_ci_high": 2.67, "p_wilcoxon": smallest_wilcoxon_p(runs),
             "p_wilcoxon_holm": min(1.0, states * smallest_wilcoxon_p(runs))} for j in range(states)]  # fmt: skip
    return pd.DataFrame(rows)


@pytest.mark.parametrize("states", [1, 6, 36])
def test_the_paired_line_says_when_its_test_cannot_reach_significance(states):
    """At the run count where Holm's smallest attainable p first falls below 0.05 the note goes,
    and one run fewer it is there (the threshold computed, not a fixed n)."""
    needed = runs_to_reach(states)
    assert states * smallest_wilcoxon_p(needed) < SIGNIFICANCE <= states * smallest_wilcoxon_p(needed - 1)
    assert "no state can differ" in summary_lines(_paired_table(needed - 1, states))[0]
    assert f"needs >= {needed} runs" in summary_lines(_paired_table(needed - 1, states))[0]
    assert "no state can differ" not in summary_lines(_paired_table(needed, states))[0]
    assert math.floor(math.log2(2 * states / SIGNIFICANCE)) + 1 == needed  # 2 m 2^-n < 0.05 (40 m is no power of 2)


@pytest.mark.slow
def test_a_sweep_with_a_failed_cell_exits_non_zero_and_keeps_the_others(tmp_path):
    """One cell refused (a bad value found in the cell), one run: exit status 3, the finished
    cell's outputs are kept, the failed cell's summary says why."""
    sweep = tmp_path / "sweep"
    args = [sys.executable, "-m", "quadest.app.cli", "-m", "model=linear", "estimator=[ekf]", "runs=2",
            "duration=0.5", "progress=false", "output.figures=false", "cache.enabled=false",
            "estimator.ekf.smoother=none,bogus", f"hydra.sweep.dir={sweep}"]  # fmt: skip
    env = {**os.environ, "QUADEST_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=tmp_path, env=env)
    assert done.returncode == 3, done.stderr[-2000:]
    assert "quadest: 1 of 2 sweep cells failed" in done.stderr
    assert (sweep / "0" / "metrics.csv").is_file()
    assert '"status": "failed"' in (sweep / "1" / "summary.json").read_text()


def test_a_refused_value_raises_config_error_in_process():
    """The same checks guard :func:`quadest.app.job.run_job` (what scripts and tests call)."""
    with pytest.raises(ConfigError, match=r"estimator\.srukf\.alpha"):
        run_job(compose_config(["estimator.srukf.alpha=1e-10"]), ROOT / "never-written")
    assert not (ROOT / "never-written").exists()


class _Refuses:
    """Work whose estimator refuses its configuration when it runs (what validation cannot see)."""

    def run(self, label, node, settings):
        raise ConfigError(f"estimator.{label}.gain", 2.0, "must be < 1")

    def failed(self, label, reason, settings):
        raise AssertionError(f"recorded as a failed result: {reason}")

    def shippable(self) -> bool:
        return True


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.slow
def test_an_estimator_refusing_its_configuration_fails_the_job_not_its_runs(workers):
    from quadest.app.estimator_runs import RunSettings, run_estimators
    from quadest.app.schema import CacheConf
    from quadest.cache.lookup import JobCache

    nodes = {"a": {"kind": "ekf"}, "b": {"kind": "ekf"}}
    with pytest.raises(ConfigError, match=r"estimator\.[ab]\.gain"):
        run_estimators(
            _Refuses(), nodes, JobCache.for_job(CacheConf(enabled=False), None), RunSettings(50.0, 0), workers
        )


def test_a_plain_sweeps_report_names_its_swept_keys(tmp_path):
    """``quadest -m runs=2,3 seed=1``: the command line sweeps ``runs`` (no sweeper params), fixes
    ``seed`` (also in the params here, so the command line's single value wins)."""
    from quadest.aggregate.report import aggregate

    (tmp_path / "multirun.yaml").write_text(
        "hydra:\n  sweeper:\n    params:\n      seed: 1,2\n      model.x: 0.1,0.2\n"
        "  overrides:\n    task:\n    - runs=2,3\n    - seed=1\n    - estimator=[ekf,ukf]\n"
    )
    report = aggregate(tmp_path).read_text()
    swept = next(line for line in report.splitlines() if line.startswith("- swept: "))
    assert json.loads(swept.removeprefix("- swept: ")) == {"model.x": "0.1,0.2", "runs": "2,3"}


@pytest.mark.parametrize("progress", [True, False])
def test_a_long_job_prints_progress_lines_unless_progress_is_off(capsys, monkeypatch, tmp_path, progress):
    import quadest.app.pipeline as pipeline

    monkeypatch.setattr(pipeline, "is_long", lambda runs, duration, sample_period: True)
    overrides = ["model=linear", "estimator=[ekf,ukf]", "runs=2", "duration=0.5", f"progress={progress}",
                 "workers=1", "cache.enabled=false", "output.figures=false"]  # fmt: skip
    run_job(compose_config(overrides), tmp_path / "job")
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("quadest: progress: ")]
    if not progress:
        assert lines == []
        return
    assert lines[0].startswith("quadest: progress: making the data: 2 runs")
    assert [line.split(" (")[0] for line in lines[-2:]] == [
        "quadest: progress: ekf done, 1 of 2 estimators",
        "quadest: progress: ukf done, 2 of 2 estimators",
    ]


def test_a_job_is_long_from_a_million_run_steps():
    assert not sizing.is_long(50, 20.0, 0.01)  # the default job: 50 x 2001
    assert sizing.is_long(500, 20.0, 0.01) and sizing.is_long(1, 1e4, 0.01)


def test_a_smoothers_backward_pass_counts_in_the_size():
    """The K transitions' gains and residuals of each smoother, 2 K B n² floats (docs/smoothers.md)."""
    base = sizing.job_bytes(10, 101, 4, 2, 1, 3)
    assert sizing.job_bytes(10, 101, 4, 2, 1, 3, smoothers=1) - base == 8 * 2 * 100 * 10 * 4 * 4


def test_the_summary_line_says_why_an_estimators_runs_were_flagged():
    """An estimator that could not run at all (every run flagged with one exception's text, as
    :func:`quadest.montecarlo.results.failed_result` records it) prints that text, not a bare
    "N of N runs diverged"; a genuine divergence prints its first flagged run's reason; none, nothing."""
    crashed = {"failure_reasons": {"0": "RuntimeError: exploded", "1": "RuntimeError: exploded"}}
    assert failure_note(crashed, 2) == " (every run: RuntimeError: exploded)"
    diverged = {"failure_reasons": {"7": "state bound exceeded at step 40", "3": "non-finite state at step 12"}}
    assert failure_note(diverged, 10) == " (run 3: non-finite state at step 12)"
    assert failure_note({"failure_reasons": {}}, 5) == ""
