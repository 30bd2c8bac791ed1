"""Every test runs with a result cache of its own in a temporary folder (``QUADEST_CACHE_DIR``,
inherited by the ``quadest`` subprocesses the tests start): the suite never reads or writes the
user's cache (``~/.cache/quadest``), and no test is served results another test computed.
Module- and session-scoped fixtures share one temporary cache.

Every test belongs to one layer (docs/testing.md, "Layers"): ``unit``, ``integration`` or
``hygiene``, the marker its file's row of ``LAYERS`` gives it unless the test carries one of the
three itself. ``slow`` (more than about a second alone on the idle 2-core development machine) is
marked on the test, whatever its layer."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import pytest

from quadest.cache.location import ENV_VAR


@pytest.fixture(scope="session", autouse=True)
def _session_cache(tmp_path_factory):
    root = tmp_path_factory.mktemp("quadest-cache")
    before = os.environ.get(ENV_VAR)
    os.environ[ENV_VAR] = str(root / "shared")
    yield root
    if before is None:
        os.environ.pop(ENV_VAR, None)
    else:
        os.environ[ENV_VAR] = before


_numbers = itertools.count()


@pytest.fixture(autouse=True)
def _test_cache(_session_cache, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(_session_cache / f"test{next(_numbers)}"))


LAYER_MARKERS = ("unit", "integration", "hygiene")
"""The layers; every test carries exactly one (``slow`` is orthogonal to them)."""

LAYERS: dict[str, str] = {
    "test_ahrs_anchors.py": "unit",
    "test_attitude.py": "unit",
    "test_attitude_metrics.py": "unit",
    "test_behaviours_closed_loop.py": "unit",
    "test_behaviours_config.py": "unit",
    "test_behaviours_kernels.py": "unit",
    "test_behaviours_pipeline.py": "integration",
    "test_behaviours_replay.py": "unit",
    "test_behaviours_sensors.py": "unit",
    "test_behaviours_smoothing.py": "unit",
    "test_behaviours_statistics.py": "unit",
    "test_benchmarks_quick.py": "integration",
    "test_cache.py": "integration",
    "test_cache_keys_property.py": "integration",
    "test_captions.py": "integration",
    "test_cli.py": "integration",
    "test_closed_loop.py": "unit",
    "test_compact_aggregate.py": "integration",
    "test_conformance_models.py": "unit",
    "test_conformance_nonlinear.py": "unit",
    "test_conformance_sensors.py": "unit",
    "test_consistency_bands.py": "integration",
    "test_cross_job.py": "unit",
    "test_doc_numbers.py": "hygiene",
    "test_docs_site.py": "hygiene",
    "test_estimator_interfaces.py": "unit",
    "test_euroc.py": "unit",
    "test_experiment_command.py": "integration",
    "test_failures_visible.py": "integration",
    "test_filterpy_batched.py": "unit",
    "test_formatting.py": "unit",
    "test_gauss_hermite_grid.py": "unit",
    "test_gaussian_filter_family.py": "unit",
    "test_gaussian_steps.py": "unit",
    "test_group_nis.py": "unit",
    "test_import_graph.py": "hygiene",
    "test_ins.py": "unit",
    "test_kernels.py": "unit",
    "test_launchers.py": "integration",
    "test_layers.py": "hygiene",
    "test_line_of_sight.py": "unit",
    "test_measurement_residual.py": "unit",
    "test_metric_parts.py": "unit",
    "test_model_job_defaults.py": "unit",
    "test_model_plugins.py": "integration",
    "test_mutation_list.py": "hygiene",
    "test_noise_laws.py": "unit",
    "test_numerics.py": "unit",
    "test_orphans.py": "integration",
    "test_paired.py": "unit",
    "test_particle_count.py": "unit",
    "test_particle_fast_mode.py": "unit",
    "test_particle_filters.py": "unit",
    "test_particle_kernels.py": "unit",
    "test_pcrlb.py": "unit",
    "test_pendulum_book.py": "integration",
    "test_pipeline.py": "integration",
    "test_plugin_integration.py": "unit",
    "test_plugins.py": "integration",
    "test_provenance.py": "integration",
    "test_python_api.py": "integration",
    "test_quadrotor_model.py": "unit",
    "test_quaternion.py": "unit",
    "test_ranking.py": "unit",
    "test_recorded_data.py": "unit",
    "test_reentry.py": "integration",
    "test_registry.py": "unit",
    "test_replay.py": "unit",
    "test_replay_timing.py": "unit",
    "test_replay_truth.py": "integration",
    "test_repository_hygiene.py": "hygiene",
    "test_reproductions.py": "unit",
    "test_reproductions_csv.py": "hygiene",
    "test_reproductions_sequential.py": "unit",
    "test_resampling.py": "unit",
    "test_results_manifest.py": "hygiene",
    "test_robust.py": "unit",
    "test_roughening.py": "unit",
    "test_rules.py": "unit",
    "test_scenario_plugins.py": "integration",
    "test_science_gaps.py": "integration",
    "test_seed001_flown_truth.py": "unit",
    "test_seed001_rates.py": "unit",
    "test_seed003_closed_loop.py": "unit",
    "test_seed004_landing.py": "unit",
    "test_sensor_plugins.py": "integration",
    "test_sensor_rates.py": "unit",
    "test_sequential.py": "unit",
    "test_sequential_runs.py": "integration",
    "test_sigma_point_family.py": "unit",
    "test_smoothers.py": "unit",
    "test_smoothing_runs.py": "integration",
    "test_srukf_identities.py": "unit",
    "test_streams.py": "unit",
    "test_streams_property.py": "integration",
    "test_style.py": "hygiene",
    "test_sweeps.py": "integration",
    "test_toolbox_bot.py": "unit",
    "test_trajectory_errors.py": "unit",
    "test_tuning.py": "integration",
    "test_typed_settings.py": "integration",
    "test_validation_models.py": "integration",
    "test_versus_best.py": "unit",
}
"""Test file → the layer of its tests (docs/testing.md, "Layers"). A new test file gets a row here;
a test that belongs to another layer than its file's carries that layer's marker itself."""


def layer_of(item: pytest.Item) -> str | None:
    """The layer ``item`` carries itself, else its file's row of ``LAYERS``."""
    own = [name for name in LAYER_MARKERS if item.get_closest_marker(name) is not None]
    if len(own) > 1:
        layers = ", ".join(LAYER_MARKERS)
        raise pytest.UsageError(f"{item.nodeid} is marked {' and '.join(own)}: a test has one layer ({layers})")
    return own[0] if own else LAYERS.get(Path(item.path).name)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        layer = layer_of(item)
        if layer is not None and item.get_closest_marker(layer) is None:
            item.add_marker(layer)
