"""A Gauss–Hermite grid too large for the model is a configuration error: refused before any work
when the model's dimension already rules it out, and a failed job (never runs that "diverge")
when only the augmented dimension (state + process + measurement noise) does."""

from __future__ import annotations

import pytest

from helpers import compose_config
from quadest.app.job import run_job
from quadest.app.validate import validate
from quadest.errors import ConfigError
from quadest.numerics.rules import GaussHermiteRule


def test_the_grid_limit_is_p_to_the_n_against_the_rules_maximum():
    rule = GaussHermiteRule(3)
    n = 1
    while 3 ** (n + 1) <= rule.max_points:
        n += 1
    assert rule.size_problem(n) is None  # 3^n fits
    assert "3^" in rule.size_problem(n + 1)  # 3^(n+1) does not


def test_a_grid_too_large_for_the_state_is_refused_before_any_work(tmp_path):
    with pytest.raises(ConfigError, match=r"estimator\.ghkf\.p.*3\^15"):
        validate(compose_config(["model=ins", "estimator=[ghkf]"]))


@pytest.mark.integration
def test_a_grid_too_large_only_when_augmented_fails_the_job(tmp_path):
    """UNGM: n = 1 passes validation at p = 100, the augmented dimension 3 (100^3 points) does not."""
    cfg = compose_config(["model=ungm", "estimator=[ghkf]", "estimator.ghkf.p=100", "estimator.ghkf.augmented=true",
                          "runs=2", "duration=1", "cache.enabled=false"])  # fmt: skip
    validate(cfg)
    with pytest.raises(ConfigError, match=r"ghkf\.rule.*100\^3"):
        run_job(cfg, tmp_path / "job")
