"""Data from a file (quadest/simulation/recorded.py): one recorded run read from JSON, CSV or NPZ
is the same data whatever the format, and a file that does not fit the job is refused with one
line naming the key."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadest.config.settings import DataSettings
from quadest.errors import ConfigError
from quadest.models.book_pendulum import BookPendulumModel
from quadest.models.schemas import BookPendulumModelConf
from quadest.simulation.book_pendulum_data import build_pendulum_data
from quadest.simulation.recorded import read_recordings, recorded_data, resolve_recording

BOOK = "sarkka-svensson-2023/pendulum.json"


def _recording(K=6, seed=3):
    rng = np.random.default_rng(seed)
    t = 0.01 * np.arange(1, K + 1)
    return t, rng.standard_normal((K, 2)), rng.standard_normal((K, 1))


def _write_all(tmp_path):
    t, x, y = _recording()
    (tmp_path / "r.json").write_text(json.dumps({"T": t.tolist(), "X": x.T.tolist(), "Y": y[:, 0].tolist()}))
    rows = ["time,x:angle,x:rate,z:sin_angle"] + [
        ",".join(repr(float(v)) for v in (a, b, c, d)) for a, (b, c), (d,) in zip(t, x, y, strict=True)
    ]
    (tmp_path / "r.csv").write_text("\n".join(rows) + "\n")
    np.savez(tmp_path / "r.npz", time=t, measurements=y, truth=x)
    return t, x, y


@pytest.mark.parametrize("suffix", ["json", "csv", "npz"])
def test_every_format_reads_the_same_recording(tmp_path, suffix):
    t, x, y = _write_all(tmp_path)
    (rec,) = read_recordings(tmp_path / f"r.{suffix}")
    assert np.array_equal(rec.time, t) and np.array_equal(rec.truth, x) and np.array_equal(rec.measurements, y)
    assert rec.inputs is None


def _settings(runs=1, period=0.01, recording=BOOK):
    return DataSettings(runs=runs, seed=0, duration=5.0, sample_period=period,
                        model=BookPendulumModelConf(recording=recording))  # fmt: skip


def test_the_books_file_becomes_one_run_started_a_step_before_its_first_sample():
    data = build_pendulum_data(_settings())
    book = json.loads(resolve_recording(BOOK).read_text())
    assert data.measurements.shape == (1, 501, 1) and data.truth.shape == (1, 501, 2)
    assert np.array_equal(data.truth[0, 1:], np.array(book["X"]).T)
    assert np.array_equal(data.measurements[0, 1:, 0], book["Y"])
    assert data.time[1] == book["T"][0] and data.time[0] == pytest.approx(0.0, abs=1e-15)
    assert np.array_equal(data.truth[0, 0], [1.5, 0.0]) and np.array_equal(data.x0[0], [0.0, 0.0])
    assert np.array_equal(data.P0, np.eye(2))


@pytest.mark.parametrize(
    ("settings", "key"),
    [(_settings(runs=2), "runs"), (_settings(period=0.02), "sample_period"),
     (_settings(recording="no/such/file.json"), "model.recording")],
)  # fmt: skip
def test_a_recording_that_does_not_fit_the_job_is_refused_naming_the_key(settings, key):
    with pytest.raises(ConfigError) as err:
        build_pendulum_data(settings)
    assert str(err.value).startswith(f"{key}=")
    assert "\n" not in str(err.value)


def test_a_measurement_of_the_wrong_size_is_refused(tmp_path):
    t, x, _ = _recording()
    (tmp_path / "r.npz").write_bytes(b"")
    np.savez(tmp_path / "r.npz", time=t, measurements=x)
    model = BookPendulumModel(0.01, 9.81, 0.01, 0.1, 1)
    with pytest.raises(ConfigError, match=r"model\.recording"):
        recorded_data(_settings(), model, read_recordings(tmp_path / "r.npz"), np.zeros((1, 2)), np.eye(2))
