"""Data from a file: recorded runs (time stamps, measurements, optionally the true states and the
inputs) replayed as the Monte Carlo data of a job, so a filter comparison can run on data nobody
simulated. Each recording is one run (``runs`` must equal their number); deterministic filters
give the same numbers every time.

Formats (docs/models.md), ``K`` samples per recording, the filters starting one sample period
before the first (sample 0, whose truth is the model's known initial state or NaN):

- **JSON**: an object with ``T`` (or ``time``), ``Y`` (``measurements``) and optionally ``X``
  (``truth``) and ``U`` (``inputs``), or a list of such objects. Arrays may be stored either way
  round (``(K, d)`` or ``(d, K)``, the layout of Särkkä & Svensson's companion files).
- **CSV**: one recording; a header with ``time``, the measurement columns ``z:<name>``, and
  optionally ``x:<name>`` and ``u:<name>``.
- **NPZ**: arrays ``time`` (K,) or (R, K), ``measurements`` (R, K, m) or (K, m), and optionally
  ``truth`` and ``inputs``.
- **EuRoC layout**: a folder with ``mav0/imu0/data.csv`` and
  ``mav0/state_groundtruth_estimate0/data.csv`` (:mod:`quadest.simulation.euroc`): the IMU as the
  inputs, the reference at the IMU's time stamps as the truth, no measurements.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.base import FilterModel
from quadest.montecarlo import MonteCarloData
from quadest.montecarlo.streams import run_seed_sequences
from quadest.sensors.record import SensorRecord
from quadest.simulation.euroc import IMU_CSV, REFERENCE_CSV, check_euroc_folder, read_euroc
from quadest.simulation.recording import Recording
from quadest.simulation.validation_data import simulation_labels

_PACKAGE = Path(__file__).resolve().parents[1]
_ALIASES = {"time": ("time", "T", "t"), "measurements": ("measurements", "Y", "y", "z"),
            "truth": ("truth", "X", "x"), "inputs": ("inputs", "U", "u")}  # fmt: skip


def resolve_recording(path: str) -> Path:
    """``path`` as given when it exists (a file, or a folder in EuRoC layout whose two CSV headers
    are checked here, before any work); a relative path is looked up in quadest's shipped
    ``data/`` folder first (the wheel's copy, then the repository's).

    Raises:
        ConfigError: ``model.recording`` names nothing, or a folder without the EuRoC files or columns.
    """
    given = Path(path)
    if not given.is_absolute():
        for root in (_PACKAGE / "data", _PACKAGE.parents[1] / "data"):
            if (root / given).is_file():
                return root / given
    if given.is_file():
        return given
    if given.is_dir():
        try:
            check_euroc_folder(given)
        except ValueError as exc:
            raise ConfigError("model.recording", path, f"an EuRoC-layout folder: {exc}") from None
        return given
    allowed = "an existing JSON, CSV or NPZ file or EuRoC-layout folder (relative: in quadest's data/)"
    raise ConfigError("model.recording", path, allowed)


def recording_files(path: str) -> list[Path]:
    """The files ``model.recording`` = ``path`` is read from (the file itself, or a EuRoC folder's two
    CSV files): what the data cache keys by content (:func:`quadest.cache.keys.data_material`)."""
    found = resolve_recording(path)
    return [found / IMU_CSV, found / REFERENCE_CSV] if found.is_dir() else [found]


def _rows(values, K: int | None, what: str) -> np.ndarray:
    """``values`` as a (K, d) array: a vector becomes one column; (d, K) is transposed."""
    a = np.asarray(values, dtype=float)
    if a.ndim == 1:
        return a[:, None]
    if a.ndim != 2:
        raise ValueError(f"{what} must be a vector or a matrix, got shape {a.shape}")
    if K is not None and a.shape[0] != K and a.shape[1] == K:
        return a.T
    return a


def _pick(record: dict, key: str):
    for alias in _ALIASES[key]:
        if alias in record:
            return record[alias]
    return None


def _from_mapping(record: dict, where: str) -> Recording:
    time, z = _pick(record, "time"), _pick(record, "measurements")
    if time is None or z is None:
        raise ValueError(f"{where}: a recording needs time stamps and measurements (keys T/time and Y/measurements)")
    t = np.asarray(time, dtype=float).ravel()
    K = t.size
    truth, inputs = _pick(record, "truth"), _pick(record, "inputs")
    return Recording(
        t,
        _rows(z, K, "measurements"),
        None if truth is None else _rows(truth, K, "truth"),
        None if inputs is None else _rows(inputs, K, "inputs"),
    )


def _read_csv(path: Path) -> list[Recording]:
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows or "time" not in rows[0]:
        raise ValueError(f"{path}: a CSV recording needs a header with 'time' and 'z:<name>' columns")
    columns = list(rows[0])

    def block(prefix: str) -> np.ndarray | None:
        names = [c for c in columns if c.startswith(prefix)]
        return np.array([[float(r[c]) for c in names] for r in rows]) if names else None

    z = block("z:")
    if z is None:
        raise ValueError(f"{path}: a CSV recording needs measurement columns named 'z:<name>'")
    return [Recording(np.array([float(r["time"]) for r in rows]), z, block("x:"), block("u:"))]


def _read_npz(path: Path) -> list[Recording]:
    with np.load(path) as npz:
        arrays = {key: npz[key] for key in npz.files}
    time = arrays.get("time")
    if time is None or "measurements" not in arrays:
        raise ValueError(f"{path}: an NPZ recording needs the arrays 'time' and 'measurements'")
    if time.ndim == 1:
        arrays = {key: value[None] for key, value in arrays.items()}
    runs = arrays["time"].shape[0]
    return [
        Recording(*(arrays[key][r] if key in arrays else None for key in ("time", "measurements", "truth", "inputs")))
        for r in range(runs)
    ]


def read_recordings(path: str | Path) -> list[Recording]:
    """Every recording of a JSON, CSV or NPZ file or of an EuRoC-layout folder (module docstring)."""
    path = Path(path)
    if path.is_dir():
        return [read_euroc(path)]
    suffix = path.suffix.lower()
    if suffix == ".json":
        content = json.loads(path.read_text())
        records = content if isinstance(content, list) else [content]
        return [_from_mapping(r, f"{path} [{i}]") for i, r in enumerate(records)]
    if suffix == ".csv":
        return _read_csv(path)
    if suffix == ".npz":
        return _read_npz(path)
    raise ValueError(f"{path}: a recording is a .json, .csv or .npz file")


def check_run_count(settings: DataSettings, recordings: list[Recording]) -> None:
    """One recording per run, all of one length.

    Raises:
        ConfigError: ``runs`` is not the number of recordings, or their lengths differ.
    """
    runs = int(settings.runs)
    if runs != len(recordings):
        raise ConfigError("runs", runs, f"{len(recordings)}: the number of recorded runs in the file")
    if any(r.time.size != recordings[0].time.size for r in recordings):
        raise ConfigError("model.recording", "runs of different lengths", "recordings of one length")


IMU_STEP_RTOL = 0.01
"""A recorded IMU's time steps may differ from ``sample_period`` by 1 % (a logger's clock jitters:
EuRoC's stamps by well under a microsecond in 5 ms); a dropped sample is refused."""


def read_imu_recordings(settings: DataSettings) -> list[Recording]:
    """The recordings of ``model.recording`` for a model driven by an IMU (``model=ins``,
    ``model=attitude``), one per run: each with the IMU samples ``[ω̃, f̃]`` as measured as its
    inputs (K, 6) and the INS state ``[q, p, v, b_g, b_a]`` as its truth (K, 16), cut to its first
    ``settings.duration`` seconds (all of it when shorter).

    Raises:
        ConfigError: ``model.recording`` cannot be read or lacks those columns, or ``runs`` is not
            the number of recordings.
    """
    path = settings.model.recording
    try:
        recordings = read_recordings(resolve_recording(path))
    except ConfigError:
        raise
    except ValueError as exc:
        raise ConfigError("model.recording", path, str(exc)) from None
    for r in recordings:
        if r.inputs is None or r.inputs.shape[1] != 6 or r.truth is None or r.truth.shape[1] != 16:
            allowed = "IMU inputs [ω̃, f̃] (6 columns) and the INS truth [q, p, v, b_g, b_a] (16 columns) per sample"
            raise ConfigError("model.recording", path, allowed)
    end = 0.5 * float(settings.sample_period) + float(settings.duration)
    kept = [r.time <= r.time[0] + end for r in recordings]
    recordings = [
        Recording(r.time[k], r.measurements[k], r.truth[k], r.inputs[k], r.notes)
        for r, k in zip(recordings, kept, strict=True)
    ]
    check_run_count(settings, recordings)
    return recordings


def recorded_data(
    settings: DataSettings,
    model: FilterModel,
    recordings: list[Recording],
    x0_est: np.ndarray,
    P0: np.ndarray,
    initial_truth: np.ndarray | None = None,
    *,
    starts_at_first_sample: bool = False,
    step_rtol: float = 1e-9,
    sensors: Mapping[str, SensorRecord] | None = None,
    labels: Mapping[str, object] | None = None,
) -> MonteCarloData:
    """The Monte Carlo data of ``recordings``, one run each: sample 0 (the filters' start, one
    ``sample_period`` before the first time stamp; its truth ``initial_truth`` or NaN) and the
    recorded samples 1..K. With ``starts_at_first_sample`` the recording's own first sample is
    sample 0 instead (its truth, input and measurement as recorded; ``initial_truth`` unused): a
    recording whose first input drives the first step, as an IMU's does. A recording without truth
    gets NaN truth (its errors are then NaN). ``sensors`` are further sensors' records (the aiding
    of an INS), ``labels`` further labels beside the job's.

    Raises:
        ConfigError: ``runs`` is not the number of recordings, the recordings differ in length,
            their time step is not ``sample_period`` (to a relative ``step_rtol``: a logger's
            clock jitters), or a measurement has not ``model.m`` components.
    """
    check_run_count(settings, recordings)
    runs, K = int(settings.runs), recordings[0].time.size
    T = float(settings.sample_period)
    lead = 0 if starts_at_first_sample else 1
    first = recordings[0].time
    time = first if starts_at_first_sample else np.concatenate([[first[0] - T], first])
    steps = np.diff(time)
    if not np.allclose(steps, T, rtol=step_rtol, atol=0.0):
        spread = f"{steps.mean():.6g} s on average, {steps.min():.6g} to {steps.max():.6g}"
        raise ConfigError("sample_period", T, f"the recording's time step ({spread})")
    if any(r.measurements.shape != (K, model.m) for r in recordings):
        raise ConfigError("model.recording", "measurements", f"{model.m} component(s) per sample")
    K1 = K + lead
    truth = np.full((runs, K1, model.n), np.nan)
    z = np.zeros((runs, K1, model.m))
    inputs = np.zeros((runs, K1, model.nu))
    for i, r in enumerate(recordings):
        if r.truth is not None:
            truth[i, lead:] = r.truth
        if initial_truth is not None and lead:
            truth[i, 0] = initial_truth
        z[i, lead:] = r.measurements
        if r.inputs is not None:
            inputs[i, lead:] = r.inputs
    seeds = run_seed_sequences(int(settings.seed), runs)["estimator"]
    labels = {**simulation_labels(settings), **(labels or {})}
    return MonteCarloData(model, time, truth, np.zeros((runs, K1, 0)), inputs, z, x0_est, P0,
                          np.zeros((runs, 0)), seeds, labels, dict(sensors or {}))  # fmt: skip
