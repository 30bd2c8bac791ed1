"""The Python API (``quadest.compose``, ``make_data``, ``run_estimators``, ``tables``; docs/python-api.md):
the docs' example runs as written, the API's numbers are the ``quadest`` command's for the same
config and seed, a bad override is one :class:`~quadest.errors.ConfigError` naming its key, and
``import quadest`` stays light (the API is imported on first use)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import quadest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "python-api.md"
UNGM = ["model=ungm", "estimator=[ekf,iekf]", "runs=6", "duration=30", "sample_period=1.0", "divergence_bound=1e6",
        "progress=false", "workers=1", "cache.enabled=false"]  # fmt: skip


def docs_example() -> str:
    """The first ``python`` code block of docs/python-api.md, as it stands."""
    blocks = re.findall(r"^```python\n(.*?)^```$", PAGE.read_text(), flags=re.S | re.M)
    assert blocks, "docs/python-api.md has no python code block"
    return blocks[0]


def test_the_docs_example_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("QUADEST_CACHE_DIR", str(tmp_path / "cache"))  # computed here, not served
    namespace: dict = {"__name__": "__main__"}  # run as a script
    exec(compile(docs_example(), str(PAGE), "exec"), namespace)
    config = namespace["config"]
    runs = config.settings.experiment.runs
    assert [r.name for r in namespace["results"]] == list(config.settings.experiment.estimator) == ["ekf", "iekf"]
    assert namespace["per_run"].shape == (runs, 2)
    # no run flagged: the benchmark's errors (a few times |x| ≲ 30) are far below divergence_bound = 1e6,
    # so a flag is the machinery failing (a worker process that could not start, an estimator that raised)
    assert not namespace["metric_tables"].table["diverged"].any()
    assert "ekf" in capsys.readouterr().out


def per_run_rmse(table: pd.DataFrame) -> pd.Series:
    """Per-run RMSE of a ``metrics.csv`` table, by estimator, run, quantity and state."""
    return table.set_index(["estimator", "run", "quantity", "state"])["rmse"].astype(float).sort_index()


def test_the_api_gives_the_command_s_per_run_rmse(tmp_path):
    """The same overrides through ``quadest`` (a separate process), through the API's steps and
    through ``quadest.run_job``: the same per-run RMSE of every estimator, run and state. Each
    computes (no cache). ``metrics.csv`` holds each double's round-trip text (``repr``); the
    tolerance of a few ulps allows for numpy's SIMD reductions, whose rounding may follow the
    arrays' alignment in memory, which differs between processes."""
    out = tmp_path / "job"
    command = [str(Path(sys.executable).with_name("quadest")), *UNGM, f"hydra.run.dir={out}"]
    subprocess.run(command, check=True, capture_output=True, text=True, cwd=tmp_path)
    from_command = per_run_rmse(pd.read_csv(out / "metrics.csv"))

    config = quadest.compose(UNGM)
    data = quadest.make_data(config)
    from_api = per_run_rmse(quadest.tables(config, data, quadest.run_estimators(config, data)).table)

    quadest.run_job(config, tmp_path / "api_job")
    from_api_job = per_run_rmse(pd.read_csv(tmp_path / "api_job" / "metrics.csv"))

    assert from_command.notna().all() and len(from_command) == 2 * 6  # two estimators × 6 runs × state x
    for ours in (from_api, from_api_job):
        assert ours.index.equals(from_command.index)
        np.testing.assert_allclose(ours.to_numpy(), from_command.to_numpy(), rtol=4 * np.finfo(float).eps, atol=0)


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("runs=0", "runs"),  # out of range: the command's own range check
        ("duration=long", "duration"),  # the wrong type: OmegaConf's error
        ("model.nonsense=1", "model.nonsense"),  # a key the schema does not have
        ("model=nosuch", "model"),  # a group option that does not exist
    ],
)
def test_a_bad_override_is_one_config_error_naming_the_key(override, key):
    with pytest.raises(quadest.ConfigError) as caught:
        quadest.compose(["model=ungm", override])
    message = str(caught.value)
    assert caught.value.key == key
    assert message.startswith(f"{key}=")
    assert "\n" not in message


def test_the_step_functions_refuse_a_closed_loop_before_any_work():
    config = quadest.compose(["loop=truth", "runs=2", "duration=1.0"])
    with pytest.raises(quadest.ConfigError) as caught:
        quadest.make_data(config)
    assert caught.value.key == "loop"


def test_import_quadest_stays_light():
    """Every module of the package imports ``quadest`` first: the API (the application layer, Hydra)
    must come only on first use, else the layers below would import the whole package."""
    heavy = "('quadest.app', 'hydra', 'omegaconf')"
    code = f"import sys, quadest.numerics; print(sorted(m for m in sys.modules if m.startswith({heavy})))"
    loaded = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout.strip()
    assert loaded == "[]"
    assert set(quadest.__all__) <= set(dir(quadest))
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        quadest.nonsense
