"""Re-introduce known bugs one at a time and check that the tests named for each go red.

Usage, from the repository root::

    python tools/mutations.py            # every mutation, after a baseline run of the named tests
    python tools/mutations.py --list     # the mutations and the tests that must catch them
    python tools/mutations.py NAME ...   # only these mutations
    python tools/mutations.py --show     # with the end of pytest's report (why it failed)

For each mutation the working tree (tracked files plus untracked, non-ignored ones) is copied
to a temporary directory, one exact piece of text in one file is replaced (it must occur exactly
once, or the script stops and says so), and only the named tests run there with
``python -m pytest -x -q`` and ``PYTHONPATH=<copy>/src``, after checking that ``quadest`` is
imported from the copy. A mutation is *caught* when pytest reports failing tests, *MISSED* when
they pass. The exit status is non-zero if any mutation is missed or a run errors. Before the
mutations, the union of the named tests runs once on the unmutated copy: a test that fails
without any bug catches nothing.

The list covers the gaps found by breaking the code on purpose (diverged runs kept in the RMSE,
truth-side sensor errors, common random numbers, the PCRLB check, nonlinear conformance,
covariances, swept keys; each had no failing test before), classic sigma-point bugs, and bugs of
the kind that really happen which once passed the whole suite (a cache serving stale results,
replay timing, χ² bands, roughening). docs/testing.md describes it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Mutation:
    """Replace ``old`` (which must occur exactly once in ``file``) by ``new``; ``tests`` must fail."""

    name: str
    file: str
    old: str
    new: str
    tests: tuple[str, ...]


GAPS = "tests/test_science_gaps.py::"
NONLINEAR = "tests/test_conformance_nonlinear.py::"
VALIDATION = "tests/test_validation_models.py::"
PCRLB = "tests/test_pcrlb.py::"
IDENTITIES = "tests/test_srukf_identities.py::"
RULES = "tests/test_rules.py::"
FAMILY = "tests/test_sigma_point_family.py::"
INTERFACES = "tests/test_estimator_interfaces.py::"
CACHE_KEYS = "tests/test_cache_keys_property.py::"
PIPELINE = "tests/test_pipeline.py::"
CROSS_JOB = "tests/test_cross_job.py::"
REPLAY_TIMING = "tests/test_replay_timing.py::"
REPLAY_TRUTH = "tests/test_replay_truth.py::"
BANDS = "tests/test_consistency_bands.py::"
ROUGHENING = "tests/test_roughening.py::"
PARTICLE_KERNELS = "tests/test_particle_kernels.py::"
STEPS = "tests/test_gaussian_steps.py::"
SMOOTHERS = "tests/test_smoothers.py::"
SMOOTHING_RUNS = "tests/test_smoothing_runs.py::"
SEQUENTIAL = "tests/test_sequential.py::"
SEQUENTIAL_RUNS = "tests/test_sequential_runs.py::"
VISIBLE = "tests/test_failures_visible.py::"
METRIC_PARTS = "tests/test_metric_parts.py::"
GROUP_NIS = "tests/test_group_nis.py::"
GAUSSIAN_FAMILY = "tests/test_gaussian_filter_family.py::"
PENDULUM_BOOK = "tests/test_pendulum_book.py::"
FAST_PF = "tests/test_particle_fast_mode.py::"

MUTATIONS = (
    Mutation(
        "the output folder's probe made in the temporary folder instead",
        "src/quadest/app/cli.py",
        'os.rmdir(tempfile.mkdtemp(prefix=".quadest-probe-", dir=existing))',
        'os.rmdir(tempfile.mkdtemp(prefix=".quadest-probe-", dir=tempfile.gettempdir()))',
        (VISIBLE + "test_a_folder_whose_file_system_takes_no_new_folder_is_refused",),
    ),
    Mutation(
        "an unbounded Fieller interval printed as nan",
        "src/quadest/evaluation/paired.py",
        "    if np.isnan(low) or np.isnan(high):\n",
        "    if False:\n",
        ("tests/test_paired.py::test_an_unbounded_fieller_interval_prints_as_unbounded",),
    ),
    Mutation(
        "an estimator that could not run prints as a plain divergence",
        "src/quadest/app/cli.py",
        'return f" (every run: {reasons[first][:160]})"',
        'return ""',
        (VISIBLE + "test_the_summary_line_says_why_an_estimators_runs_were_flagged",),
    ),
    Mutation(
        "the runner never streams a step into the metric parts",
        "src/quadest/runner.py",
        "            accumulator.step(view)\n",
        "            pass\n",
        (METRIC_PARTS + "test_the_worked_example_of_docs_metrics_adds_its_column",),
    ),
    Mutation(
        "NCI signed (the inclination index) instead of the mean absolute log ratio",
        "src/quadest/metrics/credibility.py",
        "terms.mean(), np.abs(terms).mean()",
        "terms.mean(), terms.mean()",
        (METRIC_PARTS + "test_nci_and_inclination_match_the_definition_and_the_known_cases",),
    ),
    Mutation(
        "group NEES from the inverse covariance's block instead of the marginal block's inverse",
        "src/quadest/metrics/groups.py",
        "    block = rows @ np.swapaxes(rows, -1, -2)\n",
        "    block = np.linalg.inv(np.linalg.inv(factor @ np.swapaxes(factor, -1, -2))[:, index][:, :, index])\n",
        (METRIC_PARTS + "test_group_nees_uses_the_inverse_of_the_marginal_block",),
    ),
    Mutation(
        "group NIS whitened by the full S's factor (the conditional block, not the marginal one)",
        "src/quadest/metrics/groups.py",
        "        return np.sum(whiten(L, vector[:, index]) ** 2, axis=-1)\n",
        "        return np.sum(whiten(factor, vector)[:, index] ** 2, axis=-1)\n",
        (GROUP_NIS + "test_group_nis_is_the_inverse_of_the_marginal_block_at_the_steps_each_measurement_updated",),
    ),
    Mutation(
        "a sensor's group NIS averaged over every step, not the steps it reported",
        "src/quadest/metrics/groups.py",
        'out[f"{self.prefix}_{group}"] = self.sum[:, j] / self.count[:, j]',
        'out[f"{self.prefix}_{group}"] = self.sum[:, j] / (self.mean_t.shape[0] - 1)',
        (GROUP_NIS + "test_group_nis_is_the_inverse_of_the_marginal_block_at_the_steps_each_measurement_updated",
         GROUP_NIS + "test_a_consistent_kalman_filters_groups_are_chi_square_of_their_size"),
    ),
    Mutation(
        "a sensor's NIS band share over every step, not its samples",
        "src/quadest/metrics/consistency.py",
        "        expected &= scheduled\n",
        "        expected &= True\n",
        (GROUP_NIS + "test_group_nis_is_the_inverse_of_the_marginal_block_at_the_steps_each_measurement_updated",
         GROUP_NIS + "test_a_consistent_kalman_filters_groups_are_chi_square_of_their_size"),
    ),
    Mutation(
        "a measurement group judged against the whole measurement's dof",
        "src/quadest/metrics/groups.py",
        'super().__init__(batch, "nis", {g: len(index) for g, (_, index) in self.groups.items()})',
        'super().__init__(batch, "nis", {g: batch.model.m for g in self.groups})',
        (GROUP_NIS + "test_a_consistent_kalman_filters_groups_are_chi_square_of_their_size",
         GROUP_NIS + "test_an_over_confident_r_on_one_group_leaves_its_band_and_no_other"),
    ),
    Mutation(
        "the primary NIS of a model without a primary measurement (m = 0) reported as 0, in band 0 %",
        "src/quadest/metrics/builtin.py",
        "        if not m:\n",
        "        if False:\n",
        (GROUP_NIS + "test_a_model_without_a_primary_measurement_reports_no_whole_measurement_nis",),
    ),
    Mutation(
        "steady-state window taken from the start",
        "src/quadest/metrics/windows.py",
        "steady = slice(K - max(1, round(settings.steady * K)), K)",
        "steady = slice(0, max(1, round(settings.steady * K)))",
        (METRIC_PARTS + "test_windowed_rmse_and_time_to_converge",),
    ),
    Mutation(
        "a band share from a single surviving step",
        "src/quadest/metrics/consistency.py",
        "if steps.sum() < MIN_SHARE_OF_STEPS * expected.sum() or not steps.any():",
        "if not steps.any():",
        (METRIC_PARTS + "test_a_band_share_over_almost_no_steps_is_not_reported",),
    ),
    Mutation(
        "diverged runs kept in the RMSE",
        "src/quadest/montecarlo/results.py",
        "out = np.sqrt(out) if root else out\n        out[self.diverged] = np.nan\n",
        "out = np.sqrt(out) if root else out\n",
        (GAPS + "test_a_run_diverging_midway_counts_only_its_steps_before_divergence",
         GAPS + "test_summary_tables_exclude_the_diverged_runs"),
    ),
    Mutation(
        "errors accumulated after divergence",
        "src/quadest/runner.py",
        "alive = ~self.diverged\n",
        "alive = np.ones_like(self.diverged)\n",
        (GAPS + "test_a_run_diverging_midway_counts_only_its_steps_before_divergence",),
    ),
    Mutation(
        "truth-side MIMU errors doubled",
        "src/quadest/sensors/mimu.py",
        "return errors.apply(y_true) + walk + noise",
        "return 2.0 * errors.apply(y_true) - y_true + walk + noise",
        (GAPS + "test_measure_triad_applies_the_deterministic_errors_as_documented",),
    ),
    Mutation(
        "data drawn from a seed that depends on the estimator kind",
        "src/quadest/app/estimator_runs.py",
        "        data = self.data\n",
        '        data = __import__("dataclasses").replace(self.data, measurements=self.data.measurements + 1e-3 * '
        'np.random.default_rng(sum(map(ord, node.get("kind", label))))'
        '.standard_normal(self.data.measurements.shape))\n',
        (GAPS + "test_estimators_of_every_kind_see_the_same_draws_on_the_linear_model",
         GAPS + "test_estimators_of_every_kind_get_identical_data_on_the_quadrotor"),
    ),
    Mutation(
        "the closed loop bypasses the result cache",
        "src/quadest/app/pipeline.py",
        "    return JobCache.for_job(exp.cache, data_key(cfg) if exp.cache.enabled else None)\n",
        '    if exp.loop != "open":\n'
        "        return JobCache(None, None)\n"
        "    return JobCache.for_job(exp.cache, data_key(cfg) if exp.cache.enabled else None)\n",
        (PIPELINE + "test_a_closed_loop_job_is_served_from_the_cache[truth]",
         PIPELINE + "test_a_closed_loop_job_is_served_from_the_cache[estimate]"),
    ),
    Mutation(
        "a closed loop's shared flight flown again in every job",
        "src/quadest/app/closed_loop_job.py",
        'self.caches_data = self.mode != "estimate"',
        "self.caches_data = False",
        (PIPELINE + "test_a_closed_loop_job_is_served_from_the_cache[truth]",),
    ),
    Mutation(
        "the raw config handed below the application layer again (a model node left a DictConfig)",
        "src/quadest/app/settings.py",
        "values[f.name] = OmegaConf.to_object(value) if isinstance(value, DictConfig | ListConfig) else value",
        'values[f.name] = OmegaConf.to_object(value) if isinstance(value, DictConfig) and f.name != "model" else value',
        ("tests/test_typed_settings.py::test_every_job_hands_the_layers_below_typed_settings_only",),
    ),
    Mutation(
        "a worker process that dies fails every estimator still running",
        "src/quadest/app/estimator_runs.py",
        "            except BrokenProcessPool:  # a process died: run what is missing alone, below\n"
        "                continue\n",
        "",
        (PIPELINE + "test_an_estimator_that_raises_or_whose_process_dies_fails_alone[2]",),
    ),
    Mutation(
        "an estimator that raises ends the job",
        "src/quadest/app/estimator_runs.py",
        "    except Exception as exc:  # a broken estimator is recorded, never fatal to the job\n",
        "    except KeyError as exc:  # a broken estimator is recorded, never fatal to the job\n",
        (PIPELINE + "test_a_closed_loop_estimator_that_cannot_be_built_fails_alone",
         PIPELINE + "test_an_estimator_that_raises_or_whose_process_dies_fails_alone[1]"),
    ),
    Mutation(
        "a job kind writes summary.json itself",
        "src/quadest/app/replay_job.py",
        '        return Report(tables, fields, arrays, caption(data, results), "\\n".join(after) or None)\n',
        '        (finished.out_dir / "summary.json").write_text("{}")\n'
        '        return Report(tables, fields, arrays, caption(data, results), "\\n".join(after) or None)\n',
        (PIPELINE + "test_only_the_pipeline_writes_summary_json_and_the_metric_tables",),
    ),
    Mutation(
        "PCRLB 25 % too high (filters would 'beat' a true bound)",
        "src/quadest/evaluation/pcrlb.py",
        "out[k] = np.diag(P)",
        "out[k] = 1.25 * np.diag(P)",
        (VALIDATION + "test_no_filter_beats_the_pcrlb[linear-100]",),
    ),
    Mutation(
        "PCRLB called a bound on the quadrotor",
        "src/quadest/evaluation/pcrlb.py",
        "return bool(spec.pcrlb_is_bound)",
        "return True",
        (VALIDATION + "test_pcrlb_is_called_a_bound_only_where_it_is_one",),
    ),
    Mutation(
        "PCRLB transition read with the first step's input at every step",
        "src/quadest/evaluation/pcrlb.py",
        "        u_prev = u_now\n",
        "",
        (PCRLB + "test_the_transition_into_step_k_is_read_with_the_input_of_step_k_minus_1",),
    ),
    Mutation(
        "PCRLB measurement information read with the previous step's input",
        "src/quadest/evaluation/pcrlb.py",
        "H = model.H_err(data.truth[:, k], u_now, sensor)",
        "H = model.H_err(data.truth[:, k], u_prev, sensor)",
        (PCRLB + "test_the_measurement_at_step_k_is_read_with_the_input_of_step_k",),
    ),
    Mutation(
        "PCRLB without the Jacobians' spread over the runs (E[F]ᵀQ⁻¹E[F] for E[FᵀQ⁻¹F])",
        "src/quadest/evaluation/pcrlb.py",
        "prior = add_information(P, (spread_t @ Q_range_inverse @ spread).mean(axis=0))",
        "prior = P",
        (PCRLB + "test_the_covariance_form_is_tichavskys_information_recursion_on_the_ungm",),
    ),
    Mutation(
        "PCRLB ignoring the P0 it is given",
        "src/quadest/evaluation/pcrlb.py",
        "P0 = data.P0 if P0 is None else P0",
        "P0 = data.P0",
        (PCRLB + "test_the_bound_grows_with_the_initial_covariance",),
    ),
    Mutation(
        "PCRLB information added without the Joseph form's K Kᵀ",
        "src/quadest/evaluation/pcrlb.py",
        "out = A @ P @ A.T + K @ K.T",
        "out = A @ P @ A.T",
        (PCRLB + "test_with_a_rank_deficient_Q_the_bound_is_the_kalman_covariance",),
    ),
    Mutation(
        "a PCRLB cell without a number printed as a bare '-'",
        "src/quadest/evaluation/metrics.py",
        'return "left out (caption)" if left_out else "invalid: negative or non-finite variance"',
        'return "-"',
        (PCRLB + "test_a_pcrlb_cell_without_a_number_says_why",),
    ),
    Mutation(
        "W0(c) taken from the mean weights",
        "src/quadest/numerics/sigma_points.py",
        "wc[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)",
        "wc[0] = lam / (n + lam)",
        (NONLINEAR + "test_ut_filters_have_the_closed_form_moments",),
    ),
    Mutation(
        "beta ignored",
        "src/quadest/numerics/sigma_points.py",
        "wc[0] = lam / (n + lam) + (1.0 - alpha**2 + beta)",
        "wc[0] = lam / (n + lam) + (1.0 - alpha**2)",
        (NONLINEAR + "test_ut_filters_have_the_closed_form_moments",),
    ),
    Mutation(
        "wrong sign of the W0(c) rank-one term",
        "src/quadest/numerics/rules.py",
        "1.0 if wc0 >= 0 else -1.0",
        "1.0",
        (NONLINEAR + "test_ut_filters_have_the_closed_form_moments",
         IDENTITIES + "test_srukf_matches_extended_precision_ukf_at_small_alpha"),
    ),
    Mutation(
        "W0(c) downdate skipped",
        "src/quadest/numerics/rules.py",
        "return [(np.sqrt(abs(wc0)) * D[..., 0, :, None], 1.0 if wc0 >= 0 else -1.0)]",
        "return []",
        (NONLINEAR + "test_ut_filters_have_the_closed_form_moments",),
    ),
    Mutation(
        "square-root filter reports Sᵀ S instead of S Sᵀ (covariance only)",
        "src/quadest/estimators/sigma_point.py",
        "return self.S @ _t(self.S)",
        "return _t(self.S) @ self.S",
        (IDENTITIES + "test_srukf_matches_extended_precision_ukf_at_small_alpha",),
    ),
    Mutation(
        "UT sweep stops passing beta to the UKF",
        "experiments/sweep_ut_params.yaml",
        "\n  ukf:\n    alpha: ${sweep.alpha}\n    beta: ${sweep.beta}\n",
        "\n  ukf:\n    alpha: ${sweep.alpha}\n",
        ("tests/test_sweeps.py::test_every_swept_key_reaches_what_it_names[sweep_ut_params]",),
    ),
    Mutation(
        "sensor.error_scale not applied",
        "src/quadest/models/quadrotor_config.py",
        ".scaled(error_scale)",
        "",
        ("tests/test_sweeps.py::test_every_swept_key_reaches_what_it_names[sweep_sensor_errors]",),
    ),
    Mutation(
        "fifth-degree cubature axis weight with the wrong sign",
        "src/quadest/numerics/rules.py",
        "np.full(2 * n, (4.0 - n) / (2.0 * (n + 2.0) ** 2)),",
        "np.full(2 * n, (n - 4.0) / (2.0 * (n + 2.0) ** 2)),",
        (RULES + "test_fifth_degree_cubature_integrates_quintics_exactly",),
    ),
    Mutation(
        "central-difference second-order columns dropped",
        "src/quadest/numerics/rules.py",
        "return np.concatenate([self._first_order(D, n), self._second_order(D, n)], axis=-1)",
        "return self._first_order(D, n)",
        (FAMILY + "test_dd1_keeps_first_order_terms_only_and_cdkf_the_second_order_too",),
    ),
    Mutation(
        "augmented filter ignores the model's noise function",
        "src/quadest/estimators/sigma_point.py",
        "X_pred = self.model.f_noise(X[..., :ns], X[..., ns : ns + q], u)",
        "X_pred = self.model.f(X[..., :ns], u) + X[..., ns : ns + q]",
        (FAMILY + "test_augmented_filter_uses_the_models_noise_functions",),
    ),
    Mutation(
        "runner errors by plain subtraction instead of the model's boxminus",
        "src/quadest/runner.py",
        "err = model.boxminus(est.mean, truth)",
        "err = est.mean - truth",
        (INTERFACES + "test_angle_filter_with_boxplus_equals_the_unwrapped_filter",),
    ),
    Mutation(
        "further sensors never used",
        "src/quadest/runner.py",
        "if rec.available[k]]",
        "if False]",
        (INTERFACES + "test_several_sensors_at_their_own_rates_equal_sequential_kalman_updates",),
    ),
    Mutation(
        "random estimators seeded from the truth's start stream",
        "src/quadest/runner.py",
        "est.set_generators([np.random.default_rng(seed) for seed in start.estimator_seeds])",
        "est.set_generators([np.random.default_rng(np.random.SeedSequence(i)) for i in range(B)])",
        (INTERFACES + "test_generators_come_from_the_datas_estimator_seeds",),
    ),
    Mutation(
        "a collapsed particle cloud taken for divergence",
        "src/quadest/runner.py",
        "        if not self.is_cloud:\n",
        "        if True:\n",
        (INTERFACES + "test_singular_cloud_covariance_makes_nees_unavailable_not_a_divergence",),
    ),
    Mutation(
        "batched filterpy UKF updates every run with run 0's measurement points",
        "src/quadest/estimators/filterpy_ukf.py",
        "filt.update_evaluated(z[i], hx[i], u[i])",
        "filt.update_evaluated(z[i], hx[0], u[i])",
        ("tests/test_filterpy_batched.py::test_batched_model_evaluation_gives_the_per_run_numbers",),
    ),
    Mutation(
        "per-run adapters keep a run whose mean stopped being finite",
        "src/quadest/estimators/base.py",
        "        bad = runs[~finite]\n",
        "        bad = runs[:0]\n",
        (INTERFACES + "test_per_run_adapter_flags_a_run_whose_mean_stops_being_finite_without_raising",),
    ),
    Mutation(
        "per-run adapters never check the covariance",
        "src/quadest/estimators/base.py",
        "            finite &= np.isfinite(self._cov[runs]).all((-2, -1))\n",
        "            finite = finite.copy()\n",
        (INTERFACES + "test_per_run_adapter_flags_a_run_whose_mean_stops_being_finite_without_raising",),
    ),
    Mutation(
        "diagonal Gaussian noise drawn with the variance instead of the standard deviation",
        "src/quadest/models/base.py",
        "            return e @ self._noise_factor(C).T\n        e *= scale\n",
        "            return e @ self._noise_factor(C).T\n        e *= scale**2\n",
        (INTERFACES + "test_gaussian_noise_log_density_and_sampling",),
    ),
    Mutation(
        "diagonal Gaussian log-density whitened by the variance",
        "src/quadest/models/base.py",
        "(e * (1.0 / scale)) ** 2",
        "(e * (1.0 / scale**2)) ** 2",
        (INTERFACES + "test_gaussian_noise_log_density_and_sampling",),
    ),
    Mutation(
        "diagonal Gaussian log-density taken for a semi-definite covariance",
        "src/quadest/models/base.py",
        " and np.all(diagonal > 0) else None",
        " else None",
        (INTERFACES + "test_gaussian_noise_log_density_and_sampling",),
    ),
    Mutation(
        "robust: true ignored by the family's filters",
        "src/quadest/estimators/robust_params.py",
        "huber_settings(huber_threshold, huber_max_iterations, huber_tolerance) if robust else None",
        "None",
        ("tests/test_robust.py::test_a_filters_huber_update_is_the_m_estimate_and_its_covariance",),
    ),
    Mutation(
        "Huber fractions counting updates without measurement rows",
        "src/quadest/numerics/huber.py",
        "        if rows == 0:\n            return\n",
        "",
        ("tests/test_robust.py::test_updates_without_measurement_rows_do_not_count_in_the_huber_fractions",),
    ),
    Mutation(
        "strata selection counts one position too many",
        "src/quadest/numerics/resampling.py",
        "below -= run + 2",
        "below -= run + 1",
        ("tests/test_resampling.py::test_strata_selection_follows_the_rule_across_blocks_and_at_the_edges",),
    ),
    Mutation(
        "estimator cache key leaves out divergence_bound",
        "src/quadest/cache/keys.py",
        '            "divergence_bound": float(divergence_bound),\n',
        "",
        (CACHE_KEYS + "test_every_leaf_of_the_config_changes_the_keys_of_what_it_affects[defaults]",
         CACHE_KEYS + "test_a_job_recomputes_its_estimators_when_a_runner_setting_changes[divergence_bound]"),
    ),
    Mutation(
        "cache keys leave out the compiled-kernels backend",
        "src/quadest/cache/keys.py",
        '        "kernels": kernel_backend(),\n',
        "",
        (CACHE_KEYS + "test_the_kernels_backend_is_in_every_key",),
    ),
    Mutation(
        "code version covers only the package's top-level modules",
        "src/quadest/cache/keys.py",
        'package_dir.rglob("*.py")',
        'package_dir.glob("*.py")',
        (CACHE_KEYS + "test_editing_any_source_file_changes_the_code_version",),
    ),
    Mutation(
        "replayed accelerometer timed by sensor_combined.timestamp alone",
        "src/quadest/replay/ulog.py",
        'accel_time = _seconds((sc["timestamp"] + accel_relative)[accel_valid])',
        'accel_time = _seconds(sc["timestamp"][accel_valid])',
        (REPLAY_TIMING + "test_every_relative_timestamp_field_times_its_sensor",
         REPLAY_TIMING + "test_the_replay_measures_the_accelerometer_at_its_px4_times"),
    ),
    Mutation(
        "replayed accelerometer keeps the rows that hold no sample",
        "src/quadest/replay/ulog.py",
        "accel_valid = accel_relative != RELATIVE_TIMESTAMP_INVALID",
        "accel_valid = np.ones_like(accel_relative, dtype=bool)",
        (REPLAY_TIMING + "test_every_relative_timestamp_field_times_its_sensor",
         REPLAY_TIMING + "test_the_replay_measures_the_accelerometer_at_its_px4_times"),
    ),
    Mutation(
        "NIS band share with the state's degrees of freedom",
        "src/quadest/metrics/builtin.py",
        '"nis_in_band": fraction_inside(result.nis_mean_t, m, result.alive_t)',
        '"nis_in_band": fraction_inside(result.nis_mean_t, model.n_err, result.alive_t)',
        (BANDS + "test_band_shares_use_the_error_dimension_for_nees_and_the_measurement_dimension_for_nis[linear]",
         BANDS + "test_band_shares_use_the_error_dimension_for_nees_and_the_measurement_dimension_for_nis[attitude]"),
    ),
    Mutation(
        "roughening with the kernel-bandwidth exponent N^(-1/(n+4))",
        "src/quadest/estimators/particle.py",
        "self.N ** (-1.0 / n)",
        "self.N ** (-1.0 / (n + 4))",
        (ROUGHENING + "test_roughening_jitter_has_the_standard_deviation_of_gordon_salmond_and_smith[pf]",
         ROUGHENING + "test_roughening_jitter_has_the_standard_deviation_of_gordon_salmond_and_smith[upf]"),
    ),
    Mutation(
        "strata selection counts a position equal to a cumulative weight as below it",
        "src/quadest/numerics/particle_kernels.py",
        "counts[m - 1 + (padded[m] < c[j]) + (padded[m + 1] < c[j])] += 1",
        "counts[m - 1 + (padded[m] <= c[j]) + (padded[m + 1] <= c[j])] += 1",
        (PARTICLE_KERNELS + "test_resampling_backends_agree_on_many_uniforms_near_the_cumulative_weights[stratified]",),
    ),
    Mutation(
        "pairwise summation with blocks of 64 instead of numpy's 128",
        "src/quadest/numerics/particle_kernels.py",
        "        elif n <= 128:\n",
        "        elif n <= 64:\n",
        (PARTICLE_KERNELS + "test_normalised_weights_and_ess_equal_the_reference_bit_for_bit[1000-30.0]",),
    ),
    Mutation(
        "pairwise accumulators combined in another order",
        "src/quadest/numerics/particle_kernels.py",
        "total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))",
        "total = ((r0 + r2) + (r1 + r3)) + ((r4 + r6) + (r5 + r7))",
        (PARTICLE_KERNELS + "test_normalised_weights_and_ess_equal_the_reference_bit_for_bit[20000-0.3]",),
    ),
    Mutation(
        "compiled gather reads particles it has already overwritten",
        "src/quadest/numerics/particle_kernels.py",
        "            old[:, :] = source\n            source = old\n",
        "            old[:, :] = source\n",
        (PARTICLE_KERNELS + "test_gather_kernel_picks_the_same_particles_in_place[trailing0]",),
    ),
    Mutation(
        "compiled draws keyed by the row instead of the run",
        "src/quadest/numerics/particle_kernels.py",
        "        rng = rngs[runs[r]]\n        for k in range(out.shape[1]):",
        "        rng = rngs[r]\n        for k in range(out.shape[1]):",
        (PARTICLE_KERNELS + "test_standard_normals_draw_what_each_generator_draws_alone[shape0]",),
    ),
    Mutation(
        "compiled residual resampling reads the uniforms from the start",
        "src/quadest/numerics/particle_kernels.py",
        "out[k] = _search(c, u[k - kept])",
        "out[k] = _search(c, u[k])",
        (PARTICLE_KERNELS + "test_resampling_kernel_gives_the_reference_indices[1000-residual]",),
    ),
    Mutation(
        "compiled log-density without its normalising constant",
        "src/quadest/numerics/particle_kernels.py",
        "out[k] = -0.5 * (maha + constant) - log_det",
        "out[k] = -0.5 * maha - log_det",
        (PARTICLE_KERNELS + "test_diagonal_gaussian_log_density_kernel_equals_numpy[1]",),
    ),
    Mutation(
        "compiled UNGM transition with the first run's time index for every run",
        "src/quadest/models/validation_kernels.py",
        "out[b, k, 0] = 0.5 * v + 25.0 * v / (1.0 + v * v) + c[b]",
        "out[b, k, 0] = 0.5 * v + 25.0 * v / (1.0 + v * v) + c[0]",
        (PARTICLE_KERNELS + "test_ungm_compiled_f_and_h_equal_the_numpy_reference",),
    ),
    Mutation(
        "declared parameter ranges checked only by the pre-run validation",
        "src/quadest/estimators/base.py",
        "                if problem is not None:\n",
        "                if False:\n",
        ("tests/test_plugins.py::test_bad_parameters_are_refused_at_construction_with_a_message_naming_them"
         "[hf-huber_threshold=0.0]",),
    ),
    Mutation(
        "particle kernels loaded in the first timed call instead of at construction",
        "src/quadest/estimators/particle.py",
        "        warm_up_particle_kernels()\n",
        "",
        (PARTICLE_KERNELS + "test_constructing_a_particle_filter_loads_every_particle_kernel_before_any_timed_call",),
    ),
    Mutation(
        "linearised time update without the process noise",
        "src/quadest/estimators/gaussian_steps.py",
        "return F @ P @ _t(F) + Q",
        "return F @ P @ _t(F)",
        (STEPS + "test_linearized_steps_are_filterpys_kalman_filter_on_a_linear_model",),
    ),
    Mutation(
        "posterior covariance adds K Pyy Kᵀ",
        "src/quadest/estimators/gaussian_steps.py",
        "return symmetric(P - K @ Pyy @ _t(K))",
        "return symmetric(P + K @ Pyy @ _t(K))",
        (STEPS + "test_linearized_steps_are_filterpys_kalman_filter_on_a_linear_model",),
    ),
    Mutation(
        "vector sigma points not moved to the mean",
        "src/quadest/estimators/gaussian_steps.py",
        "X[..., :n] += x[..., None, :]",
        "X[..., :n] += 0.0",
        (STEPS + "test_every_rule_gives_the_exact_moments_of_a_linear_map[cd]",),
    ),
    Mutation(
        "manifold deviations by plain subtraction",
        "src/quadest/estimators/gaussian_steps.py",
        "return mean, boxminus(Y, mean[..., None, :])",
        "return mean, Y - mean[..., None, :]",
        (STEPS + "test_points_on_a_manifold_use_its_boxplus_and_the_mean_its_boxminus",),
    ),
    Mutation(
        "EKPF proposal conditions with the model's R instead of its own",
        "src/quadest/estimators/particle_ekpf.py",
        "moments = linearized_moments(model.h(x_pred, u), H, P_pred, self.R_proposal)",
        "moments = linearized_moments(model.h(x_pred, u), H, P_pred, model.R)",
        (STEPS + "test_ekpf_proposal_is_filterpys_kalman_step_from_every_particle",),
    ),
    Mutation(
        "smoothed covariance without the next step's smoothed covariance",
        "src/quadest/estimators/smoothing.py",
        "return symmetric(step.residual + G @ spread_next @ _t(G))",
        "return symmetric(step.residual + spread_next)",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[cov-ut]",),
    ),
    Mutation(
        "square-root smoother drops the gain on the next factor",
        "src/quadest/estimators/smoothing.py",
        "return qr_factor(np.concatenate([step.residual, G @ spread_next], axis=-1))",
        "return qr_factor(np.concatenate([step.residual, spread_next], axis=-1))",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[sqrt-ut]",),
    ),
    Mutation(
        "unscented smoother residual with G in place of Gᵀ",
        "src/quadest/estimators/smoothing.py",
        "    return G, DX - D_pred @ _t(G)",
        "    return G, DX - D_pred @ G",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[cov-cubature]",),
    ),
    Mutation(
        "smoother residual without the process noise",
        "src/quadest/estimators/sigma_point.py",
        "noise = None if sqrt_noise is None else G @ sqrt_noise",
        "noise = None",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[cov-ut]",),
    ),
    Mutation(
        "fixed lag stops one step short",
        "src/quadest/estimators/smoothing.py",
        "for j in range(end - 1, k - 1, -1):",
        "for j in range(end - 1, k, -1):",
        (SMOOTHERS + "test_fixed_lag_is_the_fixed_interval_on_the_data_up_to_k_plus_lag[mekf]",),
    ),
    Mutation(
        "FFBSi ignores the transition density",
        "src/quadest/estimators/particle_smoothing.py",
        "log_b = np.log(cloud.weights)[:, None, :] + log_transition",
        "log_b = np.log(cloud.weights)[:, None, :] + 0 * log_transition",
        (SMOOTHERS + "test_ffbsi_converges_to_the_rts_smoother_as_particles_grow[1000-300-BootstrapPF]",),
    ),
    Mutation(
        "a run the filter lost kept in the smoothed result",
        "src/quadest/runner.py",
        "    tracker.flag(filtered.diverged, 1,",
        "    tracker.flag(filtered.diverged & False, 1,",
        (SMOOTHING_RUNS + "test_a_run_the_filter_lost_is_left_out_of_the_smoothed_result",),
    ),
    Mutation(
        "MEKF smoother skips the covariance reset",
        "src/quadest/estimators/error_state_ekf.py",
        "        reset = self.model.reset_jacobian if self.reset_covariance else None",
        "        reset = None",
        (SMOOTHING_RUNS + "test_the_mekf_smoother_resets_its_covariance_as_the_filter_does[True]",),
    ),
    Mutation(
        "filterpy UKF smoother with the redrawn points in place of the propagated ones",
        "src/quadest/estimators/filterpy_ukf.py",
        "DX, D = (points - x)[None], (self.kf.propagated_points - self.kf.x)[None]",
        "DX, D = (points - x)[None], (self.kf.sigmas_f - self.kf.x)[None]",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[filterpy-ukf]",),
    ),
    Mutation(
        "filterpy EKF smoother linearised with the predicted covariance",
        "src/quadest/estimators/filterpy_ekf.py",
        "step = linearized_smoother_step(P[None], F[None], self.model.Q, factor, self.mean[None])",
        "step = linearized_smoother_step(self.kf.P[None], F[None], self.model.Q, factor, self.mean[None])",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[filterpy-ekf]",),
    ),
    Mutation(
        "per-run adapter: a run's smoother step given to another run",
        "src/quadest/estimators/base.py",
        "                step = filt.smoother_step",
        "                step = self.filters[0].smoother_step",
        (SMOOTHERS + "test_every_gaussian_smoother_is_filterpys_rts_smoother_on_a_linear_model[filterpy-ekf]",),
    ),
    Mutation(
        "replay: difference to the offline reference over the warm-up too",
        "src/quadest/app/replay_job.py",
        "            for j, rms in enumerate(rms_difference(diff, window)):",
        "            for j, rms in enumerate(rms_difference(diff, np.ones_like(window))):",
        ("tests/test_replay.py::test_smoothed_replay_writes_every_rows_difference_to_the_offline_reference",),
    ),
    Mutation(
        "replay: PX4's estimate left out of the offline reference's table",
        "src/quadest/app/replay_job.py",
        "        to_smoothed = difference_to_smoothed({**angles, PX4: ref_angles}, offline, window)",
        "        to_smoothed = difference_to_smoothed(angles, offline, window)",
        ("tests/test_replay.py::test_smoothed_replay_writes_every_rows_difference_to_the_offline_reference",),
    ),
    Mutation(
        "replay: the log's declination left out of our filters' yaw",
        "src/quadest/app/replay_job.py",
        'turned = {res.name: to_true_north(res.saved["estimate"], data.declination.deg) for res in results}',
        'turned = {res.name: res.saved["estimate"] for res in results}',
        (REPLAY_TRUTH + "test_the_logs_declination_turns_every_filters_yaw_by_it",),
    ),
    Mutation(
        "replay: the declination subtracted from the magnetic yaw",
        "src/quadest/replay/declination.py",
        "np.array([0.0, 0.0, np.radians(declination_deg)])",
        "np.array([0.0, 0.0, -np.radians(declination_deg)])",
        (REPLAY_TRUTH + "test_the_logs_declination_turns_every_filters_yaw_by_it",
         REPLAY_TRUTH + "test_turning_to_true_north_adds_the_declination_to_yaw_alone"),
    ),
    Mutation(
        "replay: the declination's value at the log's start preferred to its last change",
        "src/quadest/replay/declination.py",
        "t, value = changed[-1]",
        "t, value = changed[0]",
        (REPLAY_TRUTH + "test_the_last_logged_change_of_the_declination_counts",),
    ),
    Mutation(
        "replay: the ground truth's quaternion read scalar last",
        "src/quadest/replay/ulog.py",
        'truth_q = _unit(_vector(topics[ATTITUDE_TRUTH], "q", path, ATTITUDE_TRUTH, 4))',
        'truth_q = _unit(_vector(topics[ATTITUDE_TRUTH], "q", path, ATTITUDE_TRUTH, 4)[:, [1, 2, 3, 0]])',
        (REPLAY_TRUTH + "test_truth_equal_to_px4s_estimate_gives_px4_zero_error_in_every_state",
         REPLAY_TRUTH + "test_a_constant_yaw_offset_of_the_truth_is_px4s_yaw_and_attitude_error"),
    ),
    Mutation(
        "replay: errors against the truth over the warm-up too",
        "src/quadest/app/replay_job.py",
        "compared = window & np.isfinite(truth).all(axis=-1)",
        "compared = np.isfinite(truth).all(axis=-1)",
        (REPLAY_TRUTH + "test_truth_equal_to_px4s_estimate_gives_px4_zero_error_in_every_state",
         REPLAY_TRUTH + "test_a_constant_yaw_offset_of_the_truth_is_px4s_yaw_and_attitude_error"),
    ),
    Mutation(
        "replay: PX4's estimate scored against the ground truth's interpolation of itself",
        "src/quadest/app/replay_job.py",
        "{**{n: e[0] for n, e in turned.items()}, PX4_ROW: reference}",
        "{**{n: e[0] for n, e in turned.items()}, PX4_ROW: data.ground_truth}",
        (REPLAY_TRUTH + "test_a_constant_yaw_offset_of_the_truth_is_px4s_yaw_and_attitude_error",),
    ),
    Mutation(
        "replay: the caption silent about the log's ground truth",
        "src/quadest/app/replay_job.py",
        "NOT_APPLICABLE, (turned, truth_line(data)))",
        "NOT_APPLICABLE, (turned,))",
        (REPLAY_TRUTH + "test_a_log_without_ground_truth_writes_no_truth_errors_and_says_so",),
    ),
    Mutation(
        "a model plugin's PCRLB flag ignored (a known list again)",
        "src/quadest/evaluation/pcrlb.py",
        "return bool(spec.pcrlb_is_bound)",
        'return model_name in ("linear", "ungm", "seed001_rates")',
        ("tests/test_model_plugins.py::test_the_entry_point_registers_the_model",),
    ),
    Mutation(
        "a model's own range checks skipped",
        "src/quadest/app/validate.py",
        "    spec.validate(settings)",
        "    spec.validate",
        ("tests/test_model_plugins.py::test_bad_settings_are_refused_with_one_line",),
    ),
    Mutation(
        "every plugin sensor draws from one shared stream",
        "src/quadest/simulation/aiding.py",
        'named_streams(seed, runs, f"sensor:{name}:{s}", first_run)',
        'named_streams(seed, runs, "sensor", first_run)',
        ("tests/test_sensor_plugins.py::test_the_rangefinder_measures_the_height_from_its_own_stream",),
    ),
    Mutation(
        "the INS offers its velocity on the position's error columns",
        "src/quadest/models/ins.py",
        'error={"attitude": slice(0, 3), "position": slice(3, 6), "velocity": slice(6, 9)},',
        'error={"attitude": slice(0, 3), "position": slice(3, 6), "velocity": slice(3, 6)},',
        ("tests/test_ins.py::test_error_state_jacobians_match_finite_differences_on_the_manifold",),
    ),
    Mutation(
        "the quadrotor ignores its further sensors",
        "src/quadest/models/quadrotor.py",
        "return {name: MeasurementModel(s.h, s.R, s.names, groups=s.groups) for name, s in self.aiding.items()}",
        "return {}",
        ("tests/test_sensor_plugins.py::test_a_velocity_sensor_on_the_quadrotor_informs_the_filter",),
    ),
    Mutation(
        "the data key ignores the model and sensor plugins' source (a stale hit after an edit)",
        "src/quadest/cache/keys.py",
        '        material["plugins"] = dict(plugins)',
        "        pass",
        (
            "tests/test_model_plugins.py::test_the_data_key_covers_a_model_plugins_source",
            "tests/test_sensor_plugins.py::test_the_data_key_covers_a_sensor_plugins_source",
        ),
    ),
    Mutation(
        "a benchmark script broken where only a full run reaches (the memory child's missing import)",
        "benchmarks/bench_srukf.py",
        "from quadest.app.settings import data_settings\nfrom quadest.estimators.srukf import SRUKF",
        "from quadest.estimators.srukf import SRUKF",
        ("tests/test_benchmarks_quick.py::test_quick_mode_runs",),
    ),
    Mutation(
        "the ledger's interval loses its order under a negative scale",
        "src/quadest/aggregate/reproductions.py",
        "        low, high = high, low",
        "        pass",
        ("tests/test_reproductions.py::test_a_negative_scale_keeps_the_interval_ordered",),
    ),
    Mutation(
        "the ledger reads a CI wholly on the other side of the claim as undecided",
        "src/quadest/aggregate/verdicts.py",
        '        return "claim" if high < rule.high else "other" if low >= rule.high else "neither"',
        '        return "claim" if high < rule.high else "neither"',
        ("tests/test_reproductions.py::test_verdicts_follow_the_interval",),
    ),
    Mutation(
        "the ledger takes the raw p of a claim for its Holm-corrected p",
        "src/quadest/aggregate/verdicts.py",
        "    return [float(x) for x in holm(np.asarray(p_raw, dtype=float))]",
        "    return [float(x) for x in p_raw]",
        ("tests/test_reproductions.py::test_holm_runs_over_the_sources_claims_in_a_job_not_over_every_pair",),
    ),
    Mutation(
        "the ledger accepts a rank test that cannot pass at its run count",
        "src/quadest/aggregate/verdicts.py",
        "    if floor >= SIGNIFICANCE:",
        "    if floor > 1:",
        ("tests/test_reproductions.py::test_a_test_that_cannot_pass_at_its_run_count_is_refused",),
    ),
    Mutation(
        "the runs an undecided claim needs scale as 1/n instead of 1/sqrt(n)",
        "src/quadest/aggregate/verdicts.py",
        "    return math.ceil(runs * (half_width / distance) ** 2)",
        "    return math.ceil(runs * (half_width / distance))",
        ("tests/test_reproductions.py::test_runs_needed_follow_the_half_width_scaling",),
    ),
    Mutation(
        "the ledger lets the claims reading one runs=auto job each spend the whole alpha (no Bonferroni)",
        "src/quadest/aggregate/reproductions.py",
        "        if alpha * size > v.SIGNIFICANCE * (1 + 1e-9):",
        "        if alpha > v.SIGNIFICANCE * (1 + 1e-9):",
        ("tests/test_reproductions_sequential.py::test_claims_reading_one_job_are_held_to_a_bonferroni_level",),
    ),
    Mutation(
        "the ledger asks more runs of a comparison runs=auto already decided equivalent",
        "src/quadest/aggregate/verdicts.py",
        "        return Decision(INCONCLUSIVE, None, decision.effect_bound, reason)",
        "        return Decision(INCONCLUSIVE, decision.runs_needed, decision.effect_bound, reason)",
        ("tests/test_reproductions_sequential.py::test_an_equivalent_comparison_needs_no_more_runs",),
    ),
    Mutation(
        "a docs number over several rows takes the first row instead of its min, max or mean",
        "src/quadest/aggregate/doc_numbers.py",
        "    value = values[0] if reduce is None else REDUCERS[reduce](values)",
        "    value = values[0]",
        ("tests/test_doc_numbers.py::test_ranges_scales_and_signs",),
    ),
    Mutation(
        "runs=auto looks with a fixed 95 % interval at every look (no alpha-spending)",
        "src/quadest/evaluation/sequential.py",
        "    return np.diff(np.concatenate([[0.0], spent]))\n",
        "    return np.full(spent.shape, alpha)\n",
        (SEQUENTIAL + "test_no_effect_decides_a_sign_in_at_most_alpha_of_repetitions",),
    ),
    Mutation(
        "a runs=auto batch made from runs 0.. again",
        "src/quadest/montecarlo/streams.py",
        "for i in range(first_run, first_run + runs)]\n    per_run",
        "for i in range(runs)]\n    per_run",
        (SEQUENTIAL_RUNS + "test_the_first_fifty_runs_of_a_hundred_run_job_are_the_fifty_run_job",),
    ),
    Mutation(
        "runs=auto goes on after every comparison is decided",
        "src/quadest/app/sequential_runs.py",
        "        if decisions.settled:\n            break\n",
        "",
        (SEQUENTIAL + "test_the_job_stops_at_the_first_look_where_every_comparison_is_decided",),
    ),
    Mutation(
        "n + lambda validated in real arithmetic, not as the filter computes it",
        "src/quadest/estimators/params.py",
        "    if n + lam > 0:\n        return []",
        "    if alpha**2 * (n + kappa) > 0:\n        return []",
        (VISIBLE + "test_the_validation_of_n_plus_lambda_agrees_with_the_filters_weights",
         VISIBLE + "test_a_configuration_that_cannot_run_is_refused_naming_its_key"),
    ),
    Mutation(
        "an infinite value passes a range check",
        "src/quadest/config/ranges.py",
        "    if not math.isfinite(value):\n",
        "    if math.isnan(value):\n",
        (VISIBLE + "test_a_configuration_that_cannot_run_is_refused_naming_its_key",),
    ),
    Mutation(
        "an estimator selected twice runs once",
        "src/quadest/app/validate.py",
        "twice = sorted({name for name in names if names.count(name) > 1})",
        "twice = []",
        (VISIBLE + "test_a_configuration_that_cannot_run_is_refused_naming_its_key",),
    ),
    Mutation(
        "an estimator refusing its configuration recorded as diverged runs",
        "src/quadest/app/estimator_runs.py",
        "        return work.run(label, node, settings), True\n    except ConfigError:\n        raise\n",
        "        return work.run(label, node, settings), True\n",
        (VISIBLE + "test_an_estimator_refusing_its_configuration_fails_the_job_not_its_runs",),
    ),
    Mutation(
        "an output folder without write permission passes the check",
        "src/quadest/app/cli.py",
        "    if not os.access(existing, os.W_OK | os.X_OK):",
        "    if not os.access(existing, os.F_OK):",
        (VISIBLE + "test_an_output_folder_that_cannot_be_written_is_refused",),
    ),
    Mutation(
        "a job up to twice the machine's memory passes the size check",
        "src/quadest/app/sizing.py",
        "    if need > have:",
        "    if need > 2 * have:",
        (VISIBLE + "test_a_job_one_byte_above_the_machines_memory_is_refused",),
    ),
    Mutation(
        "a replayed log shorter than duration replays without a word",
        "src/quadest/replay/data.py",
        "    if math.isfinite(settings.duration) and held < settings.duration:",
        "    if math.isfinite(settings.duration) and held > settings.duration:",
        (VISIBLE + "test_a_log_shorter_than_the_duration_is_named",),
    ),
    Mutation(
        "a sweep with a failed cell exits 0",
        "src/quadest/app/cli.py",
        "        sys.exit(SWEEP_FAILED)",
        "        return",
        (VISIBLE + "test_a_sweep_with_a_failed_cell_exits_non_zero_and_keeps_the_others",),
    ),
    Mutation(
        "a plain -m sweep's report names only the sweeper's params",
        "src/quadest/aggregate/sweep.py",
        '    for item in (hydra.get("overrides") or {}).get("task") or []:\n'
        '        key, _, value = str(item).partition("=")\n'
        "        if _sweep_size(value) > 1:",
        "    for item in []:\n        key, value = '', ''\n        if _sweep_size(value) > 1:",
        (VISIBLE + "test_a_plain_sweeps_report_names_its_swept_keys",),
    ),
    Mutation(
        "the unreachable-significance note forgets Holm's family",
        "src/quadest/evaluation/paired.py",
        "floor = min(1.0, family * smallest_wilcoxon_p(runs))",
        "floor = min(1.0, smallest_wilcoxon_p(runs))",
        (VISIBLE + "test_the_paired_line_says_when_its_test_cannot_reach_significance",),
    ),
    Mutation(
        "the closed loop's caption leaves out the smoothers' filtering-bound note",
        "src/quadest/app/closed_loop_job.py",
        "            cfg.model.name,\n            results,\n",
        "            cfg.model.name,\n            [],\n",
        ("tests/test_captions.py::test_a_job_with_a_smoother_says_its_pcrlb_is_the_filtering_bound",),
    ),
    Mutation(
        "estimator workers outlive a killed job",
        "src/quadest/app/estimator_runs.py",
        'mp_context=multiprocessing.get_context("spawn"), **pool_options())',
        'mp_context=multiprocessing.get_context("spawn"))',
        ("tests/test_orphans.py::test_killing_a_job_kills_its_estimator_workers",),
    ),
    Mutation(
        "a sweep's joblib workers outlive a killed sweep",
        "src/quadest/app/cli.py",
        "    watch_parent()  # a launcher's worker (joblib) dies with the sweep's main process",
        "    pass",
        ("tests/test_orphans.py::test_killing_a_joblib_sweep_kills_its_launchers_workers",),
    ),
    Mutation(
        "a checkout's run-time dirty flag ignores edits to src/",
        "src/quadest/app/provenance.py",
        '"--", ":/src", ":/conf", ":/experiments")',
        '"--", ":/conf", ":/experiments")',
        ("tests/test_provenance.py::test_a_checkout_with_edited_code_says_so_at_run_time",),
    ),
    Mutation(
        "an install inside a clone reports the clone's commit",
        "src/quadest/app/provenance.py",
        'return _git("ls-files", "--error-unmatch", Path(__file__).name) is not None',
        'return _git("rev-parse", "HEAD") is not None',
        ("tests/test_provenance.py::test_a_non_editable_install_reports_its_build_record_and_says_so",),
    ),
    Mutation(
        "a single-run plugin's configuration error marks its runs diverged",
        "src/quadest/estimators/base.py",
        "            except ConfigError:  # a configuration the plugin refuses fails the job",
        "            except ZeroDivisionError:  # a configuration the plugin refuses fails the job",
        ("tests/test_estimator_interfaces.py::test_per_run_adapter_lets_a_configuration_error_fail_the_job",),
    ),
    Mutation(
        "a Gauss-Hermite grid too large for the state passes validation",
        "src/quadest/estimators/gauss_hermite.py",
        "        return [] if why is None else",
        "        return [] if True else",
        ("tests/test_gauss_hermite_grid.py::test_a_grid_too_large_for_the_state_is_refused_before_any_work",),
    ),
    Mutation(
        "a sigma-point rule the augmented dimension rules out marks every run diverged",
        "src/quadest/estimators/sigma_point.py",
        "        except ValueError as exc:  # a configuration the rule cannot serve",
        "        except ZeroDivisionError as exc:  # a configuration the rule cannot serve",
        ("tests/test_gauss_hermite_grid.py::test_a_grid_too_large_only_when_augmented_fails_the_job",),
    ),
    Mutation(
        "seed 001's flown truth keeps the process noise",
        "src/quadest/simulation/seed001_rates_data.py",
        "        process = np.zeros((runs, K1, 3))",
        '        process = np.stack([rng.standard_normal((K1, 3)) for rng in streams["process"]]) * 0.3',
        ("tests/test_seed001_flown_truth.py::test_the_flown_truth_has_no_process_noise",),
    ),
    Mutation(
        "seed 001's truth options swapped (the default loses its process noise)",
        "src/quadest/simulation/seed001_rates_data.py",
        '    if m.truth == "flown":',
        '    if m.truth != "flown":',
        ("tests/test_seed001_rates.py::test_truth_is_the_filter_model_driven_by_the_process_streams_draws",),
    ),
    Mutation(
        "seed 001's truth driven by the rotor speeds one sample late",
        "src/quadest/simulation/seed001_rates_data.py",
        "        rates[:, k] = model.f(rates[:, k - 1][:, None], rotors[:, k - 1])[:, 0] + noise[:, k]",
        "        rates[:, k] = model.f(rates[:, k - 1][:, None], rotors[:, k])[:, 0] + noise[:, k]",
        ("tests/test_seed001_flown_truth.py::test_the_flown_truth_is_the_euler_step_of_the_flown_rotor_speeds",),
    ),
    Mutation(
        "seed 001's truth option unchecked (a misspelt value runs the default)",
        "src/quadest/models/seed001_rates.py",
        "    if settings.model.truth not in TRUTHS:",
        "    if settings.model.truth is None:",
        ("tests/test_seed001_flown_truth.py::test_an_unknown_truth_is_refused_before_any_work",),
    ),
    Mutation(
        "seed 001's PCRLB called a bound whatever the truth",
        "src/quadest/simulation/seed001_rates_data.py",
        '    return labels.get("truth") == "own_model"',
        '    return labels.get("truth") is not None',
        ("tests/test_seed001_flown_truth.py::test_the_pcrlb_is_called_a_bound_only_where_the_truth_follows_the_filter_model",),
    ),
)  # fmt: skip

B_SMOOTHING = "tests/test_behaviours_smoothing.py::"
B_PIPELINE = "tests/test_behaviours_pipeline.py::"
B_KERNELS = "tests/test_behaviours_kernels.py::"
B_STATISTICS = "tests/test_behaviours_statistics.py::"
B_CONFIG = "tests/test_behaviours_config.py::"
B_SENSORS = "tests/test_behaviours_sensors.py::"
B_CLOSED_LOOP = "tests/test_behaviours_closed_loop.py::"
B_REPLAY = "tests/test_behaviours_replay.py::"

EUROC = "tests/test_euroc.py::"
TRAJECTORY = "tests/test_trajectory_errors.py::"
MUTATIONS += (  # EuRoC-layout folders and the trajectory errors (docs/models.md, docs/metrics.md)
    Mutation(
        "the EuRoC quaternion read as x, y, z, w",
        "src/quadest/simulation/euroc.py",
        '"q_RS_w", "q_RS_x", "q_RS_y", "q_RS_z",',
        '"q_RS_x", "q_RS_y", "q_RS_z", "q_RS_w",',
        (EUROC + "test_the_reader_returns_the_written_reference_and_drops_the_imu_outside_its_span",),
    ),
    Mutation(
        "the EuRoC reference interpolated component-wise, not by slerp",
        "src/quadest/simulation/euroc.py",
        "out[:, 3:7] = quat.slerp(q_lo, q_hi, fraction)",
        "out[:, 3:7] = quat.normalize(out[:, 3:7])",
        (EUROC + "test_the_reference_between_its_samples_is_exact_for_a_constant_rate_and_velocity",),
    ),
    Mutation(
        "EuRoC's R frame taken upside down",
        "src/quadest/simulation/euroc.py",
        "EARTH_FROM_EUROC = np.array([1.0, 0.0, 0.0, 0.0])",
        "EARTH_FROM_EUROC = np.array([0.0, 1.0, 0.0, 0.0])",
        (EUROC + "test_the_ins_flies_the_reference_with_the_readers_imu",),
    ),
    Mutation(
        "the IMU sample at the reference's first stamp dropped",
        "src/quadest/simulation/euroc.py",
        "inside = (imu_stamps >= ref_stamps[0])",
        "inside = (imu_stamps > ref_stamps[0])",
        (EUROC + "test_the_reader_returns_the_written_reference_and_drops_the_imu_outside_its_span",),
    ),
    Mutation(
        "recorded IMU samples taken as the means over the following step",
        "src/quadest/simulation/ins_data.py",
        "inputs=interval_means(r.inputs[None])[0])",
        "inputs=r.inputs)",
        (EUROC + "test_the_ins_flies_the_reference_with_the_readers_imu",),
    ),
    Mutation(
        "a recording on model=ins starts one period before its first sample",
        "src/quadest/simulation/imu.py",
        "starts_at_first_sample=True",
        "starts_at_first_sample=False",
        (EUROC + "test_a_recording_is_cut_to_duration_and_starts_at_its_first_sample",),
    ),
    Mutation(
        "a recording keyed in the cache by its path only",
        "src/quadest/cache/keys.py",
        "    if recording is not None:\n        files = recording_files(recording)",
        "    if recording is not None and False:\n        files = recording_files(recording)",
        (EUROC + "test_the_data_is_keyed_by_the_folders_csv_bytes",),
    ),
    Mutation(
        "the attitude model on a recording with gravity along +z",
        "src/quadest/simulation/attitude_data.py",
        "np.array([0.0, 0.0, -float(mcfg.gravity)]),",
        "np.array([0.0, 0.0, float(mcfg.gravity)]),",
        (EUROC + "test_the_attitude_model_reads_the_folder_and_predicts_its_accelerometer",),
    ),
    Mutation(
        "the recorded earth-frame acceleration differenced without the time step",
        "src/quadest/simulation/attitude_data.py",
        "np.gradient(reference[..., 7:10], time, axis=1)",
        "np.gradient(reference[..., 7:10], axis=1)",
        (EUROC + "test_the_attitude_model_reads_the_folder_and_predicts_its_accelerometer",),
    ),
    Mutation(
        "the trajectory-errors command takes the truth's attitude for the estimate's",
        "src/quadest/evaluation/trajectory_errors.py",
        "ate = absolute_error(est[:, 4:7], est[:, 0:4], ref[:, 4:7], ref[:, 0:4], kind)",
        "ate = absolute_error(est[:, 4:7], ref[:, 0:4], ref[:, 4:7], ref[:, 0:4], kind)",
        (TRAJECTORY + "test_the_command_reads_a_jobs_series_and_writes_trajectory_errors_csv",),
    ),
    Mutation(
        "Umeyama's alignment without the determinant correction (a reflection)",
        "src/quadest/metrics/trajectory.py",
        "S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt))])",
        "S = np.eye(3)",
        (TRAJECTORY + "test_a_mirrored_trajectory_is_not_aligned_by_a_reflection",),
    ),
    Mutation(
        "the alignment's translation from the centroids without the rotation",
        "src/quadest/metrics/trajectory.py",
        "return Alignment(R, mu_y - R @ mu_x)",
        "return Alignment(R, mu_y - mu_x)",
        (TRAJECTORY + "test_a_trajectory_moved_by_a_known_se3_transform_aligns_to_zero_error",),
    ),
    Mutation(
        "the 4-DoF yaw with the cross term's sign flipped",
        "src/quadest/metrics/trajectory.py",
        "np.sum(xc[:, 0] * yc[:, 1] - xc[:, 1] * yc[:, 0])",
        "np.sum(xc[:, 1] * yc[:, 0] - xc[:, 0] * yc[:, 1])",
        (TRAJECTORY + "test_a_yaw_offset_aligns_to_zero_under_4dof_and_a_tilt_does_not",),
    ),
    Mutation(
        "the ATE as the mean position error, not its RMS",
        "src/quadest/metrics/trajectory.py",
        "return float(np.sqrt(np.mean(self.position**2)))",
        "return float(np.mean(self.position))",
        (TRAJECTORY + "test_noise_orthogonal_to_the_trajectory_keeps_its_rms",),
    ),
    Mutation(
        "the RPE's rotation error taken at the pair's end, not between the relative motions",
        "src/quadest/metrics/trajectory.py",
        "E_R = dR_ref_T @ dR_est",
        "E_R = R_ref[j] @ np.swapaxes(R_est[j], -1, -2)",
        (TRAJECTORY + "test_rpe_of_a_constant_rotation_drift_is_the_rate_times_the_time_of_d",),
    ),
)

MUTATIONS += (  # behaviours that once passed every test covering their code (tests/test_behaviours_*.py)
    Mutation(
        "FFBSi weighs a backward step with the input of the step it leaves",
        "src/quadest/estimators/particle_smoothing.py",
        "cloud, u_next = clouds[k], clouds[k + 1].input",
        "cloud, u_next = clouds[k], clouds[k].input",
        (B_SMOOTHING + "test_ffbsi_draws_each_backward_step_through_the_transition_into_the_next_step",),
    ),
    Mutation(
        "a particle filter's smoother cloud keeps the measurement's input",
        "src/quadest/estimators/particle.py",
        "ParticleCloud(x_new.copy(), w.copy(), self._u_prev.copy())",
        "ParticleCloud(x_new.copy(), w.copy(), u.copy())",
        (B_SMOOTHING + "test_every_particle_filter_keeps_the_input_of_the_transition_into_its_cloud",),
    ),
    Mutation(
        "a smoothed row never marked from the cache",
        "src/quadest/app/pipeline.py",
        "row_cache[result.smoothed.name] = row_cache.get(result.name, False)",
        "row_cache[result.smoothed.name] = row_cache.get(result.smoothed.name, False)",
        (B_PIPELINE + "test_a_smoothed_row_is_marked_from_cache_exactly_as_its_filters_row",),
    ),
    Mutation(
        "work sent to worker processes whether or not it pickles",
        "src/quadest/app/estimator_runs.py",
        "return processes if processes == 1 or work.shippable() else 1",
        "return processes",
        (B_PIPELINE + "test_work_whose_model_cannot_be_pickled_runs_in_the_jobs_own_process",),
    ),
    Mutation(
        "the open loop's work called shippable without checking its model",
        "src/quadest/app/estimator_runs.py",
        "        return picklable(self.data.model)",
        "        return True",
        (B_PIPELINE + "test_work_whose_model_cannot_be_pickled_runs_in_the_jobs_own_process",),
    ),
    Mutation(
        "the compiled quadrotor f with (Iy − Ix) in the yaw equation",
        "src/quadest/models/quadrotor_kernels.py",
        "wd2 = ((ix - iy) * wp * wq",
        "wd2 = ((iy - ix) * wp * wq",
        (B_KERNELS + "test_quadrotor_kernels_equal_numpy_with_randomised_parameters",),
    ),
    Mutation(
        "the compiled quadrotor h with the x-axis drag on the y axis",
        "src/quadest/models/quadrotor_kernels.py",
        "kt0 * x[b, k, 0], kt1 * x[b, k, 1]",
        "kt0 * x[b, k, 0], kt0 * x[b, k, 1]",
        (B_KERNELS + "test_quadrotor_kernels_equal_numpy_with_randomised_parameters",),
    ),
    Mutation(
        "the compiled log-density sums 8 terms left to right",
        "src/quadest/numerics/particle_kernels.py",
        "        if r < 8:  # numpy sums fewer",
        "        if r <= 8:  # numpy sums fewer",
        (B_KERNELS + "test_compiled_diagonal_log_density_is_numpys_bit_for_bit_in_every_dimension",),
    ),
    Mutation(
        'the paired summary line counts raw p-values',
        "src/quadest/evaluation/paired.py",
        'significant = int((tested["p_wilcoxon_holm"] < SIGNIFICANCE).sum())',
        'significant = int((tested["p_wilcoxon"] < SIGNIFICANCE).sum())',
        (B_STATISTICS + "test_the_count_of_differing_states_uses_holm_adjusted_p_values",),
    ),
    Mutation(
        "the sweep's paired summary counts raw p-values",
        "src/quadest/aggregate/statistics.py",
        "{int((tested['p_wilcoxon_holm'] < SIGNIFICANCE).sum())} of",
        "{int((tested['p_wilcoxon'] < SIGNIFICANCE).sum())} of",
        (B_STATISTICS + "test_the_count_of_differing_states_uses_holm_adjusted_p_values",),
    ),
    Mutation(
        "Fieller's interval drops the covariance of numerator and denominator",
        "src/quadest/evaluation/intervals.py",
        "for x, y in ((da, da), (db, db), (da, db)))",
        "for x, y in ((da, da), (db, db), (da, 0.0 * db)))",
        (
            B_STATISTICS + "test_the_paired_comparisons_relative_ci_pairs_each_runs_numerator_and_denominator",
            "tests/test_paired.py::test_the_intervals_are_student_t_of_the_mean_and_fieller_of_the_ratio",
        ),
    ),
    Mutation(
        "the particle-count relative difference pairs each run with another run's reference",
        "src/quadest/aggregate/particle_count.py",
        "ratio_interval(after - before, before, confidence)",
        "ratio_interval(after - before, before[::-1], confidence)",
        (B_STATISTICS + "test_the_particle_count_intervals_pair_each_runs_numerator_and_denominator",),
    ),
    Mutation(
        "the particle-count ratio pairs each run with another run's denominator",
        "src/quadest/aggregate/particle_count.py",
        "fieller_interval(numerator[:, None], denominator[:, None]",
        "fieller_interval(numerator[:, None], denominator[::-1, None]",
        (B_STATISTICS + "test_the_particle_count_intervals_pair_each_runs_numerator_and_denominator",),
    ),
    Mutation(
        "a ranking row's flipped interval keeps its ends unswapped",
        "src/quadest/aggregate/ranking.py",
        "            lo, hi = min(lo, hi), max(lo, hi)\n",
        "",
        (B_STATISTICS + "test_a_ranking_rows_interval_is_ordered_and_holds_its_value_in_either_order",),
    ),
    Mutation(
        'a ranking step signed by the reference instead of the estimator',
        "src/quadest/aggregate/ranking.py",
        'sign = 1.0 if est == better else -1.0',
        'sign = 1.0 if ref == better else -1.0',
        (B_STATISTICS + "test_a_ranking_steps_sign_and_verdict_do_not_depend_on_the_estimator_order",),
    ),
    Mutation(
        'a ranking verdict read from the unsigned difference',
        "src/quadest/aggregate/ranking.py",
        '("yes" if rel < 0 else',
        '("yes" if r["rel_diff"] < 0 else',
        (B_STATISTICS + "test_a_ranking_steps_sign_and_verdict_do_not_depend_on_the_estimator_order",),
    ),
    Mutation(
        "the aggregate tables' 95 % interval with the 0.95 t quantile",
        "src/quadest/aggregate/statistics.py",
        'student_t.ppf(0.975, (n - 1)',
        'student_t.ppf(0.95, (n - 1)',
        (B_STATISTICS + "test_the_aggregate_tables_95_percent_interval_covers_95_percent",
         B_STATISTICS + "test_the_particle_count_series_95_percent_interval_covers_95_percent",),
    ),
    Mutation(
        "the mean's Student-t interval with the ddof=0 standard deviation",
        "src/quadest/evaluation/intervals.py",
        "return x.mean(axis=0), t_quantile(n, miss) * x.std(axis=0, ddof=1) / np.sqrt(n)",
        "return x.mean(axis=0), t_quantile(n, miss) * x.std(axis=0) / np.sqrt(n)",
        (B_STATISTICS + "test_the_closed_loop_control_tables_95_percent_intervals_cover_95_percent",),
    ),
    Mutation(
        'the sweep-versus-best paired interval at 90 %',
        "src/quadest/aggregate/versus_best.py",
        "half = float(mean_and_half_width(diff, 1.0 - CONFIDENCE)[1])",
        "half = float(mean_and_half_width(diff, 2.0 * (1.0 - CONFIDENCE))[1])",
        (B_STATISTICS + "test_the_paired_and_step_time_95_percent_intervals_cover_95_percent",),
    ),
    Mutation(
        "the step-time ratio's interval with a normal quantile",
        "src/quadest/aggregate/ranking.py",
        'half = stats.t.ppf(0.5 + CONFIDENCE / 2, n - 1)',
        'half = stats.norm.ppf(0.5 + CONFIDENCE / 2)',
        (B_STATISTICS + "test_the_paired_and_step_time_95_percent_intervals_cover_95_percent",),
    ),
    Mutation(
        "a scenario's transition_time left unchecked",
        "src/quadest/quadrotor/scenarios.py",
        '        require_positive(f"{prefix}.transition_time", self.transition_time)\n',
        "",
        (B_CONFIG + "test_a_transition_time_that_is_not_positive_is_refused_before_any_work",),
    ),
    Mutation(
        "the GPS R adds the drift's standard deviation",
        "src/quadest/sensors/gps.py",
        'R[0:3, 0:3] += spec.position_drift**2 * np.eye(3)',
        'R[0:3, 0:3] += spec.position_drift * np.eye(3)',
        (B_SENSORS + "test_the_gps_r_adds_the_drifts_variance_to_the_white_noises",),
    ),
    Mutation(
        "the camera's field of view reads the image size as height x width",
        "src/quadest/sensors/vision.py",
        '    width, height = spec.image_size\n    x, y, z',
        '    height, width = spec.image_size\n    x, y, z',
        (B_SENSORS + "test_the_cameras_field_of_view_is_width_by_height",),
    ),
    Mutation(
        "the camera's principal point reads the image size as height x width",
        "src/quadest/sensors/vision.py",
        '    centre = 0.5 * np.asarray(spec.image_size, dtype=float)\n    values',
        '    centre = 0.5 * np.asarray(spec.image_size[::-1], dtype=float)\n    values',
        (B_SENSORS + "test_the_cameras_field_of_view_is_width_by_height",),
    ),
    Mutation(
        'the estimate-fed quadrotor loop predicts with the inputs of step k',
        "src/quadest/closed_loop/feedback.py",
        'self.tracker.step(k, self.u_prev, u_now, plant.mimu()',
        'self.tracker.step(k, u_now, u_now, plant.mimu()',
        (B_CLOSED_LOOP + "test_the_closed_loop_filter_predicts_with_the_inputs_of_the_previous_step",),
    ),
    Mutation(
        "seed 003's EKF in predicts with the inputs of step k",
        "src/quadest/closed_loop/seed003.py",
        'self.tracker.step(k, self.u_prev, u_now, self.measurement(plant)',
        'self.tracker.step(k, u_now, u_now, self.measurement(plant)',
        (B_CLOSED_LOOP + "test_the_closed_loop_filter_predicts_with_the_inputs_of_the_previous_step",),
    ),
    Mutation(
        "seed 003's state sensor with the rate sigma on theta",
        "src/quadest/models/seed003_attitude.py",
        'np.array([s.angle, s.angle, s.rate, s.rate, s.rate])',
        'np.array([s.angle, s.rate, s.angle, s.rate, s.rate])',
        (B_CLOSED_LOOP + "test_seed003s_state_sensor_puts_the_angle_sigma_on_angles_and_the_rate_sigma_on_rates",),
    ),
    Mutation(
        'a ULog topic read from the instance listed first',
        "src/quadest/replay/ulog.py",
        'if d.name not in topics or d.multi_id < topics[d.name][0]:',
        'if d.name not in topics:',
        (B_REPLAY + "test_a_topic_logged_by_several_instances_is_read_from_instance_0",),
    ),
    Mutation(
        "the replay's magnetometer R at the filter's step",
        "src/quadest/replay/data.py",
        'Q, R_acc, R_mag, P0 = replay_noise(settings, T, mag_period,',
        'Q, R_acc, R_mag, P0 = replay_noise(settings, T, T,',
        (B_REPLAY + "test_the_replays_magnetometer_r_uses_the_magnetometers_own_sample_period",),
    ),
    Mutation(
        "the paired comparison's intervals at 90 %",
        "src/quadest/evaluation/paired.py",
        "MISS = 1.0 - CONFIDENCE",
        "MISS = 2.0 * (1.0 - CONFIDENCE)",
        (B_STATISTICS + "test_the_paired_comparisons_95_percent_intervals_cover_95_percent_at_few_runs",),
    ),
    Mutation(
        "the mean's Student-t interval with a normal quantile",
        "src/quadest/evaluation/intervals.py",
        "return float(stats.t.isf(miss / 2.0, n - 1)) if n >= 2 else np.nan",
        "return float(stats.norm.isf(miss / 2.0)) if n >= 2 else np.nan",
        (B_STATISTICS + "test_the_paired_comparisons_95_percent_intervals_cover_95_percent_at_few_runs",),
    ),
    Mutation(
        "the closed loop's work called shippable without checking its loop",
        "src/quadest/app/closed_loop_job.py",
        "        return picklable(self.loop)",
        "        return True",
        (B_PIPELINE + "test_work_whose_model_cannot_be_pickled_runs_in_the_jobs_own_process",),
    ),
    Mutation(
        "the barometer's R adds the white noise's and the bias's standard deviations",
        "src/quadest/sensors/barometer.py",
        "return self.white_noise**2 + self.bias**2 + self.bias_random_walk**2",
        "return (self.white_noise + self.bias) ** 2 + self.bias_random_walk**2",
        (B_SENSORS + "test_the_barometer_r_adds_the_variances_of_its_noise_bias_and_drift_at_mid_run",),
    ),
    Mutation(
        "an iterated update drops the prior's offset from the linearisation point",
        "src/quadest/estimators/gaussian_filter.py",
        "nu = meas.innovation(z, affine.mean) - (H @ model.boxminus(m_prior, m)[..., None])[..., 0]",
        "nu = meas.innovation(z, affine.mean)",
        (GAUSSIAN_FAMILY + "test_iekf_is_the_kalman_filter_on_a_linear_model",),
    ),
    Mutation(
        "an iterated update conditions its last iterate instead of the prior",
        "src/quadest/estimators/gaussian_filter.py",
        "S = symmetric(H @ P_prior @ _t(H) + affine.noise)",
        "S = symmetric(H @ P @ _t(H) + affine.noise)",
        (GAUSSIAN_FAMILY + "test_iplf_is_the_kalman_filter_on_a_linear_model_with_any_rule",),
    ),
    Mutation(
        "the measurement's residual ignored (a bearing not wrapped)",
        "src/quadest/models/base.py",
        "return z - predicted if self.residual is None else self.residual(z, predicted)",
        "return z - predicted",
        (GAUSSIAN_FAMILY + "test_a_wrapped_bearing_residual_is_honoured_near_pi",),
    ),
    Mutation(
        "the iterated smoother linearises a step's measurement about the previous step",
        "src/quadest/estimators/iterated_smoothing.py",
        "linearisation.measurement(model, update.sensor, nominal_m[k], nominal_P[k], update.u, _factor)",
        "linearisation.measurement(model, update.sensor, nominal_m[k - 1], nominal_P[k - 1], update.u, _factor)",
        (PENDULUM_BOOK + "test_iterated_smoothers_reproduce_the_companions_published_rmse",),
    ),
    Mutation(
        "rise time from the first sample past each level, not interpolated",
        "src/quadest/closed_loop/control_metrics.py",
        "crossing = t[prev] + frac * (t[k] - t[prev])",
        "crossing = t[k] + 0 * frac",
        ("tests/test_closed_loop.py::test_rise_time_matches_hand_computed_responses",),
    ),
    Mutation(
        "fast bootstrap step's log-likelihood with half its exponent",
        "src/quadest/numerics/particle_kernels.py",
        "            value = log_norm - 0.5 * maha\n",
        "            value = log_norm - 0.25 * maha\n",
        (FAST_PF + "test_fast_step_kernels_give_the_reference_numbers_to_round_off[False-True-True-stratified]",),
    ),
    Mutation(
        "fast mode keeps the weights of the resampled cloud",
        "src/quadest/estimators/particle.py",
        "self.logw = np.full_like(out.w, self._log_uniform)",
        "self.logw = np.log(out.w)",
        (FAST_PF + "test_fast_mode_rmse_agrees_with_exact_mode_within_monte_carlo_error[numba]",),
    ),
    Mutation(
        "the cross-job comparison takes the reference as the compared job",
        "src/quadest/aggregate/cross_job.py",
        "pd.concat([tidy(reference), tidy(job)]",
        "pd.concat([tidy(job), tidy(reference)]",
        (CROSS_JOB + "test_a_constant_ratio_gives_that_ratio_with_a_zero_width_interval",),
    ),
    Mutation(
        "the cross-job comparison accepts jobs on different seeds or run counts",
        "src/quadest/aggregate/cross_job.py",
        "if ours != theirs or len(ours) != 1:",
        "if len(ours) != 1:",
        (CROSS_JOB + "test_jobs_that_do_not_share_their_runs_are_refused_before_any_work",),
    ),
    Mutation(
        "runs paired by their order in the file, not by their index",
        "src/quadest/evaluation/paired.py",
        'sub = metrics[metrics["estimator"] == name]',
        'sub = metrics[metrics["estimator"] == name]; sub = sub.assign(run=sub.groupby("state").cumcount())',
        (CROSS_JOB + "test_runs_are_paired_by_their_index_not_by_their_order_in_the_file",),
    ),
    Mutation(
        "tests/conftest.py stops giving a test its file's layer",
        "tests/conftest.py",
        "            item.add_marker(layer)",
        "            pass",
        ("tests/test_layers.py::test_every_collected_test_carries_one_layer",),
    ),
    Mutation(
        "a test file missing from the layer table",
        "tests/conftest.py",
        '    "test_quaternion.py": "unit",\n',
        "",
        ("tests/test_layers.py::test_every_test_file_has_a_layer",),
    ),
    Mutation(
        "the reentry Jacobian drops the gravity term of d(x3 rate)/dx1",
        "src/quadest/models/reentry.py",
        "        J[:, 2, 0] += G\n",
        "",
        ("tests/test_reentry.py::test_transition_jacobian_is_the_complex_step_derivative",
         "tests/test_reentry.py::test_transition_jacobian_agrees_with_central_differences"),
    ),
    Mutation(
        "the reentry bearing residual not wrapped",
        "src/quadest/models/reentry.py",
        "wrap_angle(r[..., 1:])",
        "r[..., 1:]",
        ("tests/test_reentry.py::test_the_bearing_residual_is_wrapped",
         "tests/test_reentry.py::test_an_update_across_the_bearings_cut_moves_the_estimate_by_a_bearing_noise_only"),
    ),
    Mutation(
        "the reentry truth drawn with the filters' noise densities (its ballistic parameter wanders)",
        "src/quadest/simulation/reentry_data.py",
        "np.sqrt(np.array(m.truth_q_c, dtype=float)",
        "np.sqrt(np.array(m.q_c, dtype=float)",
        ("tests/test_reentry.py::test_the_truths_noise_enters_through_the_input_matrix",),
    ),
    Mutation(
        "the reentry position row from the first coordinate only",
        "src/quadest/models/reentry.py",
        "np.linalg.norm(estimate[..., :2] - truth[..., :2], axis=-1, keepdims=True)",
        "np.linalg.norm(estimate[..., :1] - truth[..., :1], axis=-1, keepdims=True)",
        ("tests/test_reentry.py::test_the_position_row_is_the_rmse_of_the_2d_position",
         "tests/test_reentry.py::test_the_ekfs_position_row_is_the_textbook_ekfs"),
    ),
    Mutation(
        "the pre-run UT check takes an augmented filter's dimension for the state's",
        "src/quadest/estimators/params.py",
        'if alpha is None or values.get("augmented"):',
        "if alpha is None:",
        ("tests/test_reentry.py::test_an_augmented_unscented_filter_is_checked_in_its_augmented_dimension",),
    ),
)  # fmt: skip

PYTHON_API = "tests/test_python_api.py::"
MUTATIONS += (  # the Python API (docs/python-api.md): the command's numbers, one-line errors, a light import
    Mutation(
        "the Python API's data drawn from the next seed",
        "src/quadest/app/python_api.py",
        "    return job_cache(config.settings, config.composed).data(job.make_data)[0]\n",
        "    settings = config.settings.data\n"
        '    return __import__("quadest.simulation.registry", fromlist=["build_data"]).build_data(\n'
        '        __import__("dataclasses").replace(settings, seed=settings.seed + 1)\n'
        "    )\n",
        (PYTHON_API + "test_the_api_gives_the_command_s_per_run_rmse",),
    ),
    Mutation(
        "the Python API lets Hydra's multi-line composition errors through",
        "src/quadest/app/python_api.py",
        "    except (HydraException, OmegaConfBaseException) as exc:\n",
        "    except ConfigError as exc:\n",
        (PYTHON_API + "test_a_bad_override_is_one_config_error_naming_the_key[duration=long-duration]",
         PYTHON_API + "test_a_bad_override_is_one_config_error_naming_the_key[model=nosuch-model]"),
    ),
    Mutation(
        "the Python API's error for a missing group option names no key",
        "src/quadest/app/python_api.py",
        "        return ConfigError(missing[1].replace(\"/\", \".\"), missing[2], message)\n",
        "        return ConfigError(\"overrides\", overrides, message)\n",
        (PYTHON_API + "test_a_bad_override_is_one_config_error_naming_the_key[model=nosuch-model]",),
    ),
    Mutation(
        "import quadest loads the application layer",
        "src/quadest/__init__.py",
        '__version__ = "0.1.0"\n',
        '__version__ = "0.1.0"\nfrom quadest.app import python_api  # noqa: E402, F401\n',
        (PYTHON_API + "test_import_quadest_stays_light",),
    ),
)  # fmt: skip

TOOLBOX_BOT = "tests/test_toolbox_bot.py::"
MUTATIONS += (  # the toolbox manual's bearings-only tracking (docs/toolbox-bot.md)
    Mutation(
        "model=bearings_only's bearing residual not wrapped to (-pi, pi]",
        "src/quadest/models/bearings_only.py",
        "return wrap_angle(z - predicted)",
        "return z - predicted",
        (TOOLBOX_BOT + "test_a_bearing_across_plus_minus_pi_is_a_small_residual",),
    ),
    Mutation(
        "the toolbox's turning target turns the other way (the sign of F's turn rate)",
        "src/quadest/simulation/bearings_only_data.py",
        "T[..., 2, 2], T[..., 2, 3], T[..., 3, 2], T[..., 3, 3] = c, s, -s, c",
        "T[..., 2, 2], T[..., 2, 3], T[..., 3, 2], T[..., 3, 3] = c, -s, s, c",
        (TOOLBOX_BOT + "test_the_closed_form_step_is_the_matrix_exponential",),
    ),
    Mutation(
        "the toolbox's turns one step late",
        "src/quadest/simulation/bearings_only_data.py",
        "a[b, int(start) : int(start) + L] = mean",
        "a[b, int(start) + 1 : int(start) + 1 + L] = mean",
        (TOOLBOX_BOT + "test_the_truth_steps_through_exp_F_dt_with_each_runs_turn_rates",),
    ),
    Mutation(
        "the bearing Jacobian with its columns swapped, as the toolbox manual prints it",
        "src/quadest/models/bearings_only.py",
        "H[:, :, 0] = -dy / rho2\n        H[:, :, 1] = dx / rho2",
        "H[:, :, 0] = dx / rho2\n        H[:, :, 1] = -dy / rho2",
        (TOOLBOX_BOT + "test_the_bearings_and_their_jacobian_are_the_manuals",),
    ),
    Mutation(
        "the 2-D position row as the squared distance",
        "src/quadest/models/bearings_only.py",
        "return np.linalg.norm(estimate[..., :2] - truth[..., :2], axis=-1, keepdims=True)",
        "return np.sum((estimate[..., :2] - truth[..., :2]) ** 2, axis=-1, keepdims=True)",
        (TOOLBOX_BOT + "test_the_position_error_is_the_euclidean_distance",),
    ),
    Mutation(
        "model=bearings_only's Wiener velocity Q without its position-velocity terms",
        "src/quadest/models/wiener_velocity.py",
        "return float(q) * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])",
        "return float(q) * np.array([[dt**3 / 3.0, 0.0], [0.0, dt]])",
        (TOOLBOX_BOT + "test_the_ekf_and_its_rts_smoother_equal_an_independent_implementation",),
    ),
)  # fmt: skip

MUTATIONS += (  # the ledger's narrow windows and a model's own job defaults
    Mutation(
        "a rule's window printed with three digits whatever its width",
        "src/quadest/aggregate/verdicts.py",
        "return max(3, math.ceil(math.log10(scale / (self.high - self.low))) + 2)",
        "return 3",
        ("tests/test_reproductions.py::test_a_narrow_window_prints_its_ends_and_the_value_apart",),
    ),
    Mutation(
        "a published mean's interval without the source's own Monte Carlo error",
        "src/quadest/aggregate/reproductions.py",
        "half = stats.t.isf((1.0 - confidence) / 2.0, n - 1) * spread * np.sqrt(1.0 / n + 1.0 / n_pub)",
        "half = stats.t.isf((1.0 - confidence) / 2.0, n - 1) * spread * np.sqrt(1.0 / n)",
        ("tests/test_reproductions.py::test_a_published_mean_falls_in_its_interval_as_often_as_its_confidence",),
    ),
    Mutation(
        "a model's job defaults ignored (the job's 20 s, 0.01 s and 50 for every model)",
        "src/quadest/app/schema.py",
        "return float(spec.job_defaults.get(key, fallback)) if spec is not None else float(fallback)",
        "return float(fallback)",
        ("tests/test_model_job_defaults.py::test_every_model_gets_its_own_defaults_else_the_jobs",),
    ),
    Mutation(
        "a job default outside the three keys accepted",
        "src/quadest/simulation/spec.py",
        "        if key not in JOB_DEFAULT_KEYS:",
        "        if False:",
        ("tests/test_model_job_defaults.py::test_a_bad_job_default_makes_the_spec_unusable",),
    ),
)  # fmt: skip

RESIDUAL = "tests/test_measurement_residual.py::"
WRAPPED = RESIDUAL + "test_a_wrapped_bearing_residual_keeps_every_gaussian_filter_on_the_truth"
STRADDLING = RESIDUAL + "test_sigma_points_on_both_sides_of_the_cut_average_to_the_right_bearing"

MUTATIONS += (  # every Gaussian filter conditions on the measurement's residual (a bearing across ±π)
    Mutation(
        "the sigma-point family's innovation by z − ẑ, not the measurement's residual",
        "src/quadest/estimators/sigma_point.py",
        "(z - y_pred if residual is None else residual(z, y_pred)), Sy",
        "z - y_pred, Sy",
        (WRAPPED + "[ckf]",),
    ),
    Mutation(
        "the sigma-point family averages a wrapped measurement's points arithmetically",
        "src/quadest/estimators/sigma_point.py",
        "y_pred, DY = point_mean(Y, self.rule.mean_weights(dim), np.add, residual)",
        "y_pred, DY = self._mean(Y, dim, state=False)",
        (STRADDLING + "[ckf]",),
    ),
    Mutation(
        "the batched EKFs (mekf, hf) take z − ẑ for the innovation",
        "src/quadest/estimators/error_state_ekf.py",
        "self._nu = meas.innovation(z, moments.mean)",
        "self._nu = z - moments.mean",
        (WRAPPED + "[mekf]", WRAPPED + "[hf]"),
    ),
    Mutation(
        "the fused SR-UKF update taken for a measurement with its own residual",
        "src/quadest/estimators/srukf.py",
        " or self.model.measurement().residual is not None:",
        ":",
        (WRAPPED + "[srukf]",),
    ),
    Mutation(
        "filterpy's EKF handed no residual",
        "src/quadest/estimators/filterpy_ekf.py",
        "residual=np.subtract if meas.residual is None else _column_residual(meas.residual),",
        "residual=np.subtract,",
        (WRAPPED + "[ekf]",),
    ),
    Mutation(
        "filterpy's UKF averages a wrapped measurement's points arithmetically",
        "src/quadest/estimators/filterpy_ukf.py",
        "self.kf.residual_z, self.kf.z_mean = residual, _residual_mean(residual)",
        "self.kf.residual_z, self.kf.z_mean = residual, None",
        (STRADDLING + "[ukf-alpha=1.0-beta=0.0-kappa=1.0]",),
    ),
)

RATES = "tests/test_sensor_rates.py::"

MUTATIONS += (  # a bad sensor rate: one line naming the sensor's own key and the allowed rates
    Mutation(
        "a sensor's sampling names the magnetometer's key for its bad rate",
        "src/quadest/sensors/gps.py",
        'sample_stride(spec.rate, sample_period, f"{Gps.key()}.rate")',
        'sample_stride(spec.rate, sample_period, "model.magnetometer.rate")',
        (RATES + "test_the_sampling_itself_names_the_sensors_own_key[gps]",),
    ),
    Mutation(
        "a bad rate's error gives the rule but not the allowed rates",
        "src/quadest/sensors/base.py",
        "raise ConfigError(key, rate, allowed_rates(sample_period))",
        'raise ConfigError(key, rate, f"must divide the filter rate 1/sample_period = {1.0 / sample_period:g} Hz")',
        (RATES + "test_a_bad_rate_is_refused_naming_the_sensors_own_key_and_the_allowed_rates[30.0-gps]",),
    ),
)

PARTICLE_RESIDUAL = RESIDUAL + "test_a_wrapped_bearing_residual_keeps_every_particle_filter_on_the_truth"
MUTATIONS += (  # the particle filters weigh and propose with the measurement's residual
    Mutation(
        "the particle filters' likelihood of z − h(x) instead of the residual",
        "src/quadest/estimators/particle.py",
        "residual = self.model.measurement(None).innovation(z[:, None, :], self.model.h(x_new, u))",
        "residual = z[:, None, :] - self.model.h(x_new, u)",
        (PARTICLE_RESIDUAL + "[pf]", PARTICLE_RESIDUAL + "[ilopf]"),
    ),
    Mutation(
        "the fast bootstrap step handed h(x) whatever the residual",
        "src/quadest/estimators/particle.py",
        "            if meas.residual is not None:  # the fused step forms z − hx: hand it z − r(z, hx)",
        "            if False:",
        (PARTICLE_RESIDUAL + "[pf-fast]",),
    ),
    Mutation(
        "the EKPF's proposal corrected with z − ẑ",
        "src/quadest/estimators/particle_ekpf.py",
        "model.measurement(None).innovation(z[:, None, :], moments.mean)",
        "z[:, None, :] - moments.mean",
        (PARTICLE_RESIDUAL + "[ekpf]",),
    ),
    Mutation(
        "the UPF's proposal corrected with z − ẑ",
        "src/quadest/estimators/particle_upf.py",
        "model.measurement(None).innovation(z[:, None, :], y_pred)",
        "z[:, None, :] - y_pred",
        (PARTICLE_RESIDUAL + "[upf]",),
    ),
)  # fmt: skip

REGISTRY = "tests/test_registry.py::"
MUTATIONS += (  # one registry behaviour for every extension kind (src/quadest/config/registry.py)
    Mutation(
        "an in-repository extension that breaks its contract skipped silently",
        "src/quadest/config/registry.py",
        "        if issues:\n"
        "            _add(problems, name, f\"{kind.kind} {origin} does not meet the contract: {'; '.join(issues)}\")\n",
        "        if issues:\n",
        (
            REGISTRY + "test_an_in_repository_contract_break_is_one_line_naming_it",
            REGISTRY + "test_a_broken_in_repository_estimator_is_named_when_its_yaml_is_selected",
        ),
    ),
    Mutation(
        "two in-repository extensions with one name: the last one wins",
        "src/quadest/config/registry.py",
        'claims.append((f"{module_name}.{attribute}", obj))',
        'claims[:] = [(f"{module_name}.{attribute}", obj)]',
        (REGISTRY + "test_two_in_repository_extensions_with_one_name_are_an_error_naming_both",),
    ),
    Mutation(
        "two plugins with one name: the last one wins",
        "src/quadest/config/registry.py",
        "by_name.setdefault(ep.name, {}).setdefault(ep.value, ep)",
        "by_name[ep.name] = {ep.value: ep}",
        (REGISTRY + "test_two_plugins_with_one_name_are_an_error_naming_both",),
    ),
    Mutation(
        "the built-ins view returns the installed plugins too",
        "src/quadest/config/registry.py",
        "return {name: entry for name, entry in self.usable.items() if name in self.builtin}",
        "return dict(self.usable)",
        (REGISTRY + "test_the_builtins_view_leaves_installed_plugins_out",),
    ),
    Mutation(
        "a registered extension without its YAML reported as an unknown option",
        "src/quadest/app/schema.py",
        '        return missing_yaml(found, extension, f"{group}/{name}.yaml")',
        "        return None",
        (REGISTRY + "test_a_registered_extension_without_its_yaml_is_reported_as_such",),
    ),
)

SENSOR_KIT = "tests/test_conformance_sensors.py::test_a_broken_sensor_fails_on_its_bug"
MODEL_KIT = "tests/test_conformance_models.py::test_a_broken_model_fails_on_its_bug"

MUTATIONS += (  # the conformance kit's own checks (quadest.conformance.check_sensor, check_model)
    Mutation(
        "the conformance kit's Jacobian tolerance ignored",
        "src/quadest/conformance/jacobians.py",
        "tol = jacobian_tolerance(values, differences, step, largest_step)",
        "tol = np.inf",
        (SENSOR_KIT + "[WrongJacobian]", MODEL_KIT + "[WrongJacobian]"),
    ),
    Mutation(
        "check_sensor blind to draws from numpy's global generator",
        "src/quadest/conformance/sensors.py",
        "    after = np.random.get_state()",
        "    after = state",
        (SENSOR_KIT + "[GlobalDraws]",),
    ),
    Mutation(
        "check_sensor comparing only run 0 of a batch with the run alone",
        "src/quadest/conformance/sensors.py",
        "for i in range(runs):",
        "for i in range(1):",
        (SENSOR_KIT + "[OneGenerator]",),
    ),
    Mutation(
        "check_model never restricting the batch",
        "src/quadest/conformance/models.py",
        "for runs in [*range(B), slice(1, None)]:",
        "for runs in []:",
        (MODEL_KIT + "[ForgetsItsDrift]", MODEL_KIT + "[NextRun]"),
    ),
)  # fmt: skip


def tree_files() -> list[str]:
    """Tracked files that still exist, plus untracked files that are not ignored."""
    out = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return sorted({f for f in out.stdout.split("\0") if f and (ROOT / f).is_file()})


def copy_tree(files: list[str], dest: Path) -> None:
    for f in files:
        target = dest / f
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, target)


def stale(mutation: Mutation, root: Path = ROOT) -> str | None:
    """Why ``mutation`` no longer applies to the tree at ``root`` (its file is gone, or its text does
    not occur exactly once; a named test file or function is gone), or ``None``."""
    path = root / mutation.file
    if not path.is_file():
        return f"{mutation.name!r}: {mutation.file} does not exist; update the mutation"
    count = path.read_text().count(mutation.old)
    if count != 1:
        return (
            f"{mutation.name!r}: the text to replace occurs {count} times in {mutation.file} "
            f"(must be exactly once); update the mutation. Text: {mutation.old!r}"
        )
    for test in mutation.tests:
        file, _, function = test.partition("::")
        function = function.split("[")[0]
        if not (root / file).is_file() or (function and f"def {function}(" not in (root / file).read_text()):
            return f"{mutation.name!r}: the test {test} does not exist; update the mutation"
    return None


def apply(mutation: Mutation, dest: Path) -> None:
    problem = stale(mutation, dest)
    if problem is not None:
        sys.exit(f"mutations.py: {problem}")
    path = dest / mutation.file
    path.write_text(path.read_text().replace(mutation.old, mutation.new))


def environment(dest: Path) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(dest / "src"), "PYTHONDONTWRITEBYTECODE": "1"}
    env.pop("PYTEST_ADDOPTS", None)
    return env


def check_import_from(dest: Path) -> None:
    """Make sure the copy, not the installed tree, is what the tests will import."""
    out = subprocess.run(
        [sys.executable, "-c", "import quadest; print(quadest.__file__)"],
        cwd=dest, env=environment(dest), capture_output=True, text=True,
    )  # fmt: skip
    where = Path(out.stdout.strip() or "?").resolve()
    if dest.resolve() not in where.parents:
        sys.exit(f"mutations.py: quadest was imported from {where}, not from the copy {dest}: {out.stderr.strip()}")


def run_tests(dest: Path, tests: tuple[str, ...]) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests],
        cwd=dest, env=environment(dest), capture_output=True, text=True,
    )  # fmt: skip


def in_copy(files: list[str], mutation: Mutation | None, tests: tuple[str, ...]) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory(prefix="quadest-mutation-") as tmp:
        dest = Path(tmp)
        copy_tree(files, dest)
        if mutation is not None:
            apply(mutation, dest)
        check_import_from(dest)
        return run_tests(dest, tests)


def last_line(proc: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in (proc.stdout + proc.stderr).splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help="run only the mutations with these names")
    parser.add_argument("--list", action="store_true", help="list the mutations and exit")
    parser.add_argument("--no-baseline", action="store_true", help="skip the run of the tests without mutation")
    parser.add_argument("--show", action="store_true", help="print the end of pytest's report for each mutation")
    args = parser.parse_args(argv)
    chosen = [m for m in MUTATIONS if not args.names or m.name in args.names]
    unknown = set(args.names) - {m.name for m in MUTATIONS}
    if unknown:
        parser.error(f"unknown mutations {sorted(unknown)}; see --list")
    if args.list:
        for m in chosen:
            print(f"{m.name}\n    {m.file}\n    " + "\n    ".join(m.tests))
        return 0
    problems = [problem for m in chosen if (problem := stale(m)) is not None]
    if problems:
        sys.exit("mutations.py: " + "\nmutations.py: ".join(problems))
    files = tree_files()
    if not args.no_baseline:
        union = tuple(dict.fromkeys(t for m in chosen for t in m.tests))
        base = in_copy(files, None, union)
        if base.returncode != 0:
            print(f"baseline: the named tests fail without any mutation: {last_line(base)}")
            print(base.stdout[-3000:])
            return 2
        print(f"baseline: {last_line(base)}")
    failures = 0
    for m in chosen:
        proc = in_copy(files, m, m.tests)
        if proc.returncode == 1:
            verdict = "caught"
        elif proc.returncode == 0:
            verdict, failures = "MISSED", failures + 1
        else:
            verdict, failures = f"ERROR (pytest exit {proc.returncode})", failures + 1
        print(f"{verdict:>8s}  {m.name}  [{last_line(proc)}]")
        if args.show:
            print("\n".join("          " + ln for ln in proc.stdout.splitlines()[-25:]))
    print(f"{len(chosen) - failures} of {len(chosen)} mutations caught")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
