"""The caption above every job's table (quadest.evaluation.captions), built by one function for every
job kind: with a smoother of either kind and a PCRLB column, it says that the column is the
filtering bound; a replay, which has no PCRLB column, says why and nothing about a bound."""

from __future__ import annotations

import pytest

from helpers import compose_config
from quadest.app.job import run_job

SMALL = ["runs=2", "duration=1.0", "progress=false", "workers=1", "cache.enabled=false", "output.figures=false"]
KINDS = {
    "open loop": ["model=linear", "estimator=[ekf,ukf]"],
    "closed loop, loop=truth": ["loop=truth", "estimator=[ekf,ukf]"],
    "closed loop, loop=measured": ["loop=measured", "estimator=[ekf,ukf]"],
}
SMOOTHERS = {
    "fixed interval": ["estimator.ukf.smoother=fixed_interval"],
    "fixed lag": ["estimator.ukf.smoother=fixed_lag", "estimator.ukf.smoother_lag=5"],
}


def caption(tmp_path, overrides: list[str]) -> str:
    return run_job(compose_config([*SMALL, *overrides]), tmp_path / "job", overrides)["_caption"]


@pytest.mark.parametrize("smoother", list(SMOOTHERS))
@pytest.mark.parametrize("kind", list(KINDS))
def test_a_job_with_a_smoother_says_its_pcrlb_is_the_filtering_bound(tmp_path, kind, smoother):
    text = caption(tmp_path, [*KINDS[kind], *SMOOTHERS[smoother]])
    assert "PCRLB" in text and "filtering bound" in text


@pytest.mark.parametrize("kind", list(KINDS))
def test_a_job_without_a_smoother_says_nothing_of_a_filtering_bound(tmp_path, kind):
    text = caption(tmp_path, KINDS[kind])
    assert "PCRLB" in text and "filtering bound" not in text


@pytest.mark.slow
def test_a_replay_with_a_smoother_says_it_has_no_pcrlb(tmp_path):
    overrides = ["experiment=px4_replay_smoothed", "duration=8", "output.figures=false", "progress=false",
                 "workers=1", "cache.enabled=false"]  # fmt: skip
    text = run_job(compose_config(overrides), tmp_path / "job", overrides)["_caption"]
    assert "PCRLB are not reported" in text and "filtering bound" not in text
    assert text in (tmp_path / "job" / "rmse_table.md").read_text()
