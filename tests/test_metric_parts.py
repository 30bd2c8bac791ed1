"""Metrics as parts (docs/metrics.md): each measure against an independent computation written
here, the band share over almost no steps, and the columns every job kind writes against
docs/outputs.md."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers import compose_config
from quadest.aggregate.sweep import load_sweep
from quadest.app.job import run_job
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.metrics.base import BatchStart, StepView
from quadest.metrics.consistency import fraction_inside
from quadest.metrics.credibility import Credibility
from quadest.metrics.groups import GroupNEES, marginal_mahalanobis_sq
from quadest.metrics.quantiles import ErrorQuantiles
from quadest.metrics.registry import register, unregister
from quadest.metrics.settings import MetricsConf
from quadest.metrics.windows import windowed

ROOT = Path(__file__).resolve().parents[1]


class _Model:
    """The little of a filter model the metric parts read."""

    def __init__(self, names, units, groups=None, derived=(), companion=()):
        self.error_names, self.error_units = tuple(names), tuple(units)
        self.derived_error_names, self.derived_error_units = tuple(derived), ("deg",) * len(derived)
        self.companion_names, self.companion_units = tuple(companion), ("m",) * len(companion)
        self.state_groups = groups or {}
        self.n_err = len(names)


def _view(k, error, factor=None, nees=None, alive=None):
    B, n = error.shape
    factor = np.broadcast_to(np.eye(n), (B, n, n)) if factor is None else factor
    return StepView(k, error, np.zeros((B, 0)), np.zeros((B, 0)), factor,
                    np.full(B, np.nan) if nees is None else nees, np.full(B, np.nan),
                    np.ones(B, dtype=bool) if alive is None else alive)  # fmt: skip


def _hand_credibility(error, P):
    """Li, Zhao & Jilkov 2002 written out run by run with explicit inverses."""
    M = error.shape[0]
    mse = sum(np.outer(e, e) for e in error) / M
    terms = [
        10 * np.log10((e @ np.linalg.inv(Pi) @ e) / (e @ np.linalg.inv(mse) @ e))
        for e, Pi in zip(error, P, strict=True)
    ]
    return np.mean(np.abs(terms)), np.mean(terms)


def test_nci_and_inclination_match_the_definition_and_the_known_cases():
    rng = np.random.default_rng(3)
    M, n, K = 40, 3, 5
    model = _Model(["a", "b", "c"], ["m"] * 3)
    acc = Credibility().start(BatchStart(model, np.arange(K + 1) * 0.1, M))
    expected = []
    for k in range(1, K + 1):
        error = rng.normal(size=(M, n)) * [1.0, 2.0, 0.5]
        A = rng.normal(size=(M, n, n))
        P = A @ np.swapaxes(A, -1, -2) + np.eye(n)
        L = np.linalg.cholesky(P)
        nees = np.einsum("bi,bij,bj->b", error, np.linalg.inv(P), error)
        acc.step(_view(k, error, L, nees))
        expected.append(_hand_credibility(error, P))
    got = acc.finish()
    assert got["nci"] == pytest.approx(np.mean([e[0] for e in expected]), rel=1e-10)
    assert got["inclination"] == pytest.approx(np.mean([e[1] for e in expected]), rel=1e-10)
    # a filter whose covariance is its actual MSE is credible; a quarter of it is 10 log10 4 dB optimistic
    error = rng.normal(size=(M, n))
    mse = error.T @ error / M
    for scale, incl in ((1.0, 0.0), (0.25, 10 * np.log10(4.0))):
        acc = Credibility().start(BatchStart(model, np.arange(2) * 0.1, M))
        nees = np.einsum("bi,ij,bj->b", error, np.linalg.inv(scale * mse), error)
        acc.step(_view(1, error, None, nees))
        out = acc.finish()
        assert out["inclination"] == pytest.approx(incl, abs=1e-9)
        assert out["nci"] == pytest.approx(abs(incl), abs=1e-9)


def test_credibility_is_undefined_with_no_more_runs_than_states():
    model = _Model(["a", "b", "c"], ["m"] * 3)
    acc = Credibility().start(BatchStart(model, np.arange(2) * 0.1, 3))
    acc.step(_view(1, np.eye(3), None, np.ones(3)))
    assert np.isnan(acc.finish()["nci"])


def test_group_nees_uses_the_inverse_of_the_marginal_block():
    rng = np.random.default_rng(5)
    B, n = 6, 5
    A = rng.normal(size=(B, n, n))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(n)
    error = rng.normal(size=(B, n))
    index = [1, 3, 4]
    got = marginal_mahalanobis_sq(error, np.linalg.cholesky(P), index)
    expected = [error[b, index] @ np.linalg.inv(P[b][np.ix_(index, index)]) @ error[b, index] for b in range(B)]
    np.testing.assert_allclose(got, expected, rtol=1e-9)


def test_group_nees_columns_and_band_share():
    rng = np.random.default_rng(7)
    B, K = 200, 30
    model = _Model(["x", "y", "v"], ["m", "m", "m/s"], {"positions": ("x", "y"), "velocities": ("v",)})
    acc = GroupNEES().start(BatchStart(model, np.arange(K + 1) * 0.1, B))
    sums = np.zeros(B)
    for k in range(1, K + 1):
        error = rng.normal(size=(B, 3))  # unit covariance: consistent
        acc.step(_view(k, error))
        sums += error[:, 0] ** 2 + error[:, 1] ** 2
    out = acc.finish()
    np.testing.assert_allclose(out["nees_positions"], sums / K, rtol=1e-12)
    # χ²(200·2)/200 at 95 %: about 95 % of the steps inside; 30 steps, so at least ~80 % with margin
    assert out["nees_in_band_positions"] >= 0.8 and out["nees_in_band_velocities"] >= 0.8


def _hand_quantile(values, q):
    """Linear interpolation between order statistics (Hyndman & Fan 1996, definition 7)."""
    s = sorted(values)
    h = (len(s) - 1) * q
    lo = int(np.floor(h))
    return s[lo] + (h - lo) * (s[min(lo + 1, len(s) - 1)] - s[lo])


def test_error_quantiles_per_run_and_state():
    rng = np.random.default_rng(11)
    B, K = 4, 37
    model = _Model(["a", "b"], ["m", "m"])
    acc = ErrorQuantiles().start(BatchStart(model, np.arange(K + 1) * 0.1, B))
    errors = rng.standard_t(3, size=(K, B, 2))
    for k in range(1, K + 1):
        alive = np.array([True, True, True, k < 10])  # run 3 diverges at step 10
        acc.step(_view(k, errors[k - 1], alive=alive))
    out = acc.finish()
    for b in range(3):
        for j in range(2):
            e = np.abs(errors[:, b, j]).astype(np.float32).astype(float)
            assert out["abs_error_median"][b, j] == pytest.approx(_hand_quantile(e, 0.5), rel=1e-12)
            assert out["abs_error_p95"][b, j] == pytest.approx(_hand_quantile(e, 0.95), rel=1e-12)
    assert np.isnan(out["abs_error_median"][3]).all()


def test_windowed_rmse_and_time_to_converge():
    K = 100
    time = np.arange(1, K + 1) * 0.1
    alive = np.full(K, 4.0)
    rms = 1.0 + 9.0 * np.exp(-time / 0.5)  # settles to 1
    sq = (rms**2 * alive)[:, None]
    out = windowed(time, sq, alive, MetricsConf(transient=0.1, steady=0.5, settle_factor=2.0))
    assert out["transient_rmse"][0] == pytest.approx(np.sqrt(np.mean(rms[:10] ** 2)), rel=1e-12)
    steady = np.sqrt(np.mean(rms[50:] ** 2))
    assert out["steady_rmse"][0] == pytest.approx(steady, rel=1e-12)
    first = next(i for i in range(K) if all(r < 2.0 * steady for r in rms[i:]))
    assert out["time_to_converge_s"][0] == pytest.approx(time[first])


def test_a_band_share_over_almost_no_steps_is_not_reported():
    K, runs = 100, 50
    average = np.full(K + 1, 6.0)  # the χ²(6) mean: inside the band whenever it is computed
    alive = np.full(K + 1, float(runs))
    assert fraction_inside(average, 6, alive) == 1.0
    alive[2:] = 0  # every run diverged after step 1: one step
    assert np.isnan(fraction_inside(average, 6, alive))


@pytest.mark.parametrize(
    ("override", "key"),
    [("metrics.transient=0", "metrics.transient"), ("metrics.steady=1.5", "metrics.steady"),
     ("metrics.settle_factor=1", "metrics.settle_factor")],
)  # fmt: skip
def test_bad_metric_windows_fail_validation_naming_the_key(override, key):
    with pytest.raises(ConfigError) as caught:
        validate(compose_config([override]))
    assert str(caught.value).startswith(f"{key}=") and "\n" not in str(caught.value)


def _documented(section: str) -> set[str]:
    """Column names in backticks in the first column of the table under ``section`` of docs/outputs.md."""
    text = (ROOT / "docs" / "outputs.md").read_text()
    part = text[text.index(section) :]
    part = part[: part.index("\n## ", 1)] if "\n## " in part[1:] else part
    names = set()
    for line in part.splitlines():
        if line.startswith("| ") and not line.startswith("| column"):
            names |= set(re.findall(r"`([^`]+)`", line.split("|")[1]))
    return names


def _undocumented(columns, documented: set[str], labels) -> set[str]:
    """Columns not in the table: the estimators' parameters and the job's labels are a family each."""
    pattern = {re.sub(r"<[^>]+>", "", d) for d in documented if "<" in d}
    return {
        c for c in columns
        if c not in documented and c not in labels and not any(c.startswith(p) for p in pattern if p)
    }  # fmt: skip


JOBS = {
    "open": ["runs=12", "duration=0.3", "estimator=[ekf]"],
    "closed": ["loop=truth", "estimator=[ekf]", "runs=2", "duration=0.5", "scenario=attitude_steps",
               "scenario.steps=[[0.2,0.0,4.0]]", "output.saved_runs=1"],
    "replay": ["experiment=px4_replay", "duration=6.0", "estimator=[mekf]"],
    "attitude": ["model=attitude", "runs=12", "duration=0.5", "estimator=[mekf]"],
}  # fmt: skip


@pytest.mark.parametrize("kind", JOBS)
@pytest.mark.integration
@pytest.mark.slow
def test_every_job_kind_writes_the_documented_columns(kind, tmp_path):
    cfg = compose_config([*JOBS[kind], "workers=1", "progress=false", "output.figures=false", "cache.enabled=false"])
    run_job(cfg, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert all(not est["failure_reasons"] for est in summary["estimators"].values())
    labels = set(summary["labels"]) | {"seed", "runs"}
    params = {k for est in summary["estimators"].values() for k in est["parameters"]}
    metrics = pd.read_csv(tmp_path / "metrics.csv")
    assert not _undocumented(metrics.columns, _documented("## `metrics.csv`"), labels | params)
    table = pd.read_csv(tmp_path / "rmse_summary.csv")
    assert not _undocumented(table.columns, _documented("## `rmse_summary.csv`"), set())
    entry = next(iter(summary["estimators"].values()))
    assert set(summary["metric_keys"]) <= set(entry)
    assert not _undocumented(summary["metric_keys"], _documented("## Per-estimator metrics"), set())


@pytest.mark.integration
def test_the_sweep_aggregate_reads_every_declared_metric(tmp_path):
    for job in range(2):
        cfg = compose_config(["runs=12", "duration=0.3", "estimator=[ekf]", f"seed={job}", "workers=1",
                              "progress=false", "output.figures=false", "cache.enabled=false"])  # fmt: skip
        (tmp_path / str(job)).mkdir()
        run_job(cfg, tmp_path / str(job))
    cells, _, _ = load_sweep(tmp_path)
    keys = json.loads((tmp_path / "0" / "summary.json").read_text())["metric_keys"]
    assert {"nci", "inclination", "nees_in_band_velocities"} <= set(keys) <= set(cells.columns)
    assert {"abs_error_median", "abs_error_p95", "transient_rmse", "steady_rmse", "time_to_converge_s"} <= set(
        cells.columns
    )
    assert not _undocumented(cells.columns, _documented("## `rmse_summary.csv`") | _documented(
        "## Per-estimator metrics") | {"job", "ci95_low", "ci95_high", "seed"}, set())  # fmt: skip


@pytest.mark.integration
def test_the_worked_example_of_docs_metrics_adds_its_column(tmp_path):
    """The one-file metric of docs/metrics.md, registered, gives the median of |estimate − truth|
    over steps 1..K of each saved run, computed here from timeseries.npz."""
    text = (ROOT / "docs" / "metrics.md").read_text()
    code = text.split("<!-- worked-example -->\n```python\n", 1)[1].split("```", 1)[0]
    namespace: dict = {"__name__": "median_abs_error_example"}
    exec(compile(code, "docs/metrics.md", "exec"), namespace)
    metric = register(namespace["MedianAbsoluteError"]())
    try:
        cfg = compose_config(["runs=3", "duration=0.3", "estimator=[ekf]", "output.saved_runs=3", "workers=1",
                              "progress=false", "output.figures=false", "cache.enabled=false"])  # fmt: skip
        run_job(cfg, tmp_path)
    finally:
        unregister(metric.name)
    series = np.load(tmp_path / "timeseries.npz")
    expected = np.median(np.abs(series["ekf/estimate"][:, 1:] - series["truth"][:, 1:]), axis=1)  # (runs, n)
    table = pd.read_csv(tmp_path / "metrics.csv")
    filt = table[table["quantity"] == "filter"]
    got = filt.pivot(index="run", columns="state", values="median_abs_error")[list(filt["state"].unique())]
    np.testing.assert_allclose(got.to_numpy(), expected, rtol=1e-12)
    assert "median_abs_error" in pd.read_csv(tmp_path / "rmse_summary.csv").columns
