"""A model's own job defaults (``ModelSpec.job_defaults``, docs/models.md): used where neither an
experiment nor the command line sets the key, replaced by either, and checked like the rest of a spec."""

from __future__ import annotations

import dataclasses

import pytest

import quadest
from quadest.simulation.registry import model_specs
from quadest.simulation.spec import JOB_DEFAULT_KEYS, spec_problems

JOB_DEFAULTS = {"duration": 20.0, "sample_period": 0.01, "divergence_bound": 50.0}
"""The job's own values (conf/config.yaml's fallbacks), for a model that declares none."""


def job_keys(overrides: list[str]) -> dict[str, float]:
    experiment = quadest.compose(overrides).settings.experiment
    return {key: float(getattr(experiment, key)) for key in JOB_DEFAULT_KEYS}


@pytest.mark.parametrize("name", sorted(model_specs()))
def test_every_model_gets_its_own_defaults_else_the_jobs(name: str):
    declared = dict(model_specs()[name].job_defaults)
    assert job_keys([f"model={name}"]) == JOB_DEFAULTS | declared


def test_the_declaring_models_are_the_discrete_time_and_book_ones():
    """The spec values themselves, typed from their sources (docs/models.md): UNGM's 50 unit steps
    (Gordon, Salmond & Smith 1993), the UPF benchmark's 60 time steps (van der Merwe et al. 2000,
    §5.1), the book pendulum's and the toolbox's bearings-only 500 steps of 0.01 s (Särkkä & Svensson
    2023, Ex. 5.1; Hartikainen, Solin & Särkkä 2011, §3.6)."""
    assert job_keys(["model=ungm"]) == {"duration": 50.0, "sample_period": 1.0, "divergence_bound": 1.0e6}
    assert job_keys(["model=upf_benchmark"]) == {"duration": 59.0, "sample_period": 1.0, "divergence_bound": 1.0e6}
    assert job_keys(["model=book_pendulum"]) == {"duration": 5.0, "sample_period": 0.01, "divergence_bound": 50.0}
    assert job_keys(["model=bearings_only"]) == {"duration": 5.0, "sample_period": 0.01, "divergence_bound": 50.0}


def test_the_command_line_and_an_experiment_replace_a_models_default():
    assert job_keys(["model=ungm", "duration=7", "divergence_bound=3"])["duration"] == 7.0
    assert job_keys(["model=ungm", "duration=7", "divergence_bound=3"])["divergence_bound"] == 3.0
    assert job_keys(["experiment=ungm_toolbox"])["duration"] == 500.0  # its own file says 500 steps


def test_the_data_has_the_models_number_of_steps():
    data = quadest.make_data(quadest.compose(["model=ungm", "runs=2", "cache.enabled=false"]))
    assert data.truth.shape == (2, 51, 1)  # x_0 and 50 steps of one second
    assert data.time[-1] == pytest.approx(50.0)


@pytest.mark.parametrize(
    ("defaults", "problem"),
    [
        ({"runs": 5.0}, "job_defaults key 'runs' is not one of"),
        ({"duration": -1.0}, "job_defaults.duration must be a number > 0"),
        ({"sample_period": "fast"}, "job_defaults.sample_period must be a number > 0"),
    ],
)
def test_a_bad_job_default_makes_the_spec_unusable(defaults: dict, problem: str):
    spec = dataclasses.replace(model_specs()["ungm"], job_defaults=defaults)
    assert any(problem in p for p in spec_problems(spec))
