"""The result cache (docs/cache.md): a job served from it writes what a computed job writes; its
keys change with everything the data or a result depends on and with nothing else; it survives
killed jobs, concurrent writers and damaged files; disabled, it is never touched."""

from __future__ import annotations

import hashlib
import json
import pickle
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import quadest.app.estimator_runs as estimator_runs
import quadest.app.job as job
import quadest.app.open_loop_job as open_loop_job
from helpers import compose_config
from quadest.app.cli import precheck
from quadest.app.settings import data_key
from quadest.app.validate import validate
from quadest.cache import keys
from quadest.cache.cli import main as cache_main
from quadest.cache.location import default_cache_dir
from quadest.cache.store import MAGIC, CacheStore
from quadest.errors import ConfigError
from target_plugin import LinearizedKF

SMALL = ["runs=3", "duration=0.3", "progress=false", "output.figures=false", "workers=1"]
TIMING = ["step_time_us", "from_cache"]


def small_cfg(cache_dir: Path, extra: list[str] | None = None):
    return compose_config([*SMALL, f"cache.dir={cache_dir}", *(extra or [])])


@pytest.fixture
def spies(monkeypatch) -> dict[str, list]:
    """Records every data build, estimator run and PCRLB recursion of the jobs in this process."""
    calls: dict[str, list] = {"builds": [], "runs": [], "pcrlb": []}
    build, run, pcrlb = open_loop_job.build_data, estimator_runs.run_estimator, open_loop_job.pcrlb_variances

    def counting_build(cfg):
        calls["builds"].append(cfg)
        return build(cfg)

    def counting_run(name, *args, **kwargs):
        calls["runs"].append(name)
        return run(name, *args, **kwargs)

    def counting_pcrlb(data):
        calls["pcrlb"].append(data)
        return pcrlb(data)

    monkeypatch.setattr(open_loop_job, "build_data", counting_build)
    monkeypatch.setattr(open_loop_job, "pcrlb_variances", counting_pcrlb)
    monkeypatch.setattr(estimator_runs, "run_estimator", counting_run)
    return calls


def outputs(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, dict, dict]:
    summary = json.loads((folder / "summary.json").read_text())
    with np.load(folder / "timeseries.npz") as npz:
        series = {key: npz[key] for key in npz.files}
    return (
        pd.read_csv(folder / "metrics.csv"),
        pd.read_csv(folder / "rmse_summary.csv"),
        pd.read_csv(folder / "paired_comparison.csv"),
        summary,
        series,
    )


def without_timing(summary: dict) -> dict:
    out = {**summary, "cache": None}
    out["estimators"] = {
        name: {k: v for k, v in est.items() if k not in TIMING} for name, est in summary["estimators"].items()
    }
    return out


@pytest.mark.slow
def test_a_job_served_from_the_cache_writes_what_a_computed_job_writes(tmp_path, spies):
    """Cold (computed and stored), warm (everything looked up) and uncached jobs: the same
    metrics, tables, time series and summary bit for bit; the warm job reports the step times the
    cold job measured and flags its results as cached."""
    cache = tmp_path / "cache"
    cfg = small_cfg(cache, ["output.saved_runs=2"])
    job.run_job(cfg, tmp_path / "cold")
    job.run_job(cfg, tmp_path / "warm")
    job.run_job(small_cfg(cache, ["output.saved_runs=2", "cache.enabled=false"]), tmp_path / "off")
    assert len(spies["builds"]) == len(spies["pcrlb"]) == 2  # cold and off
    assert spies["runs"] == ["ekf", "ukf", "srukf"] * 2
    cold, warm, off = (outputs(tmp_path / name) for name in ("cold", "warm", "off"))

    assert not cold[0]["from_cache"].any() and warm[0]["from_cache"].all() and not off[0]["from_cache"].any()
    exact = {"check_exact": True}
    pd.testing.assert_frame_equal(warm[0].drop(columns="from_cache"), cold[0].drop(columns="from_cache"), **exact)
    pd.testing.assert_frame_equal(off[0].drop(columns=TIMING), cold[0].drop(columns=TIMING), **exact)
    for other in (warm, off):
        for got, expected in zip(other[1:3], cold[1:3], strict=True):
            pd.testing.assert_frame_equal(got, expected, **exact)
        assert without_timing(other[3]) == without_timing(cold[3])
        assert other[4].keys() == cold[4].keys()
        for key, value in cold[4].items():
            np.testing.assert_array_equal(other[4][key], value, err_msg=key)
    for name, est in warm[3]["estimators"].items():
        assert est["from_cache"] and est["step_time_us"] == cold[3]["estimators"][name]["step_time_us"]
    assert warm[3]["cache"] == {"enabled": True, "data_from_cache": True}
    assert cold[3]["cache"] == {"enabled": True, "data_from_cache": False}


DATA_CHANGES = [
    "seed=7",
    "runs=4",
    "duration=0.4",
    "sample_period=0.02",
    "sensor=tactical",
    "sensor.error_scale=2.0",
    "sensor.encoder.lines=512",
    "model.mass=0.7",
    "model.formulation=augmented",
    "model.process_noise.velocity=0.02",
    "scenario=hover",
    "scenario.altitude=2.0",
]
NOT_DATA = [
    "workers=2",
    "progress=true",
    "output.saved_runs=1",
    "output.figures=true",
    "divergence_bound=10.0",
    "estimator.srukf.alpha=0.1",
    "estimator=[srukf]",
    "+sweep.alpha=0.3",
    "objective.nees_penalty=2.0",
    "cache.enabled=false",
]


@pytest.mark.parametrize("change", DATA_CHANGES)
@pytest.mark.slow
def test_every_setting_of_the_data_changes_the_data_key(tmp_path, change):
    assert data_key(small_cfg(tmp_path, [change])) != data_key(small_cfg(tmp_path))


@pytest.mark.parametrize("change", NOT_DATA)
@pytest.mark.slow
def test_settings_that_leave_the_data_alone_keep_the_data_key(tmp_path, change):
    assert data_key(small_cfg(tmp_path, [change])) == data_key(small_cfg(tmp_path / "elsewhere"))


def test_a_new_code_version_recomputes_everything(tmp_path, spies, monkeypatch):
    cfg = small_cfg(tmp_path / "cache", ["estimator=[ekf,srukf]"])
    job.run_job(cfg, tmp_path / "a")
    monkeypatch.setattr(keys, "code_version", lambda: "another version of the package")
    job.run_job(cfg, tmp_path / "b")
    assert len(spies["builds"]) == 2 and spies["runs"] == ["ekf", "srukf"] * 2


def test_the_source_digest_follows_every_file_and_nothing_else(tmp_path):
    """Contents, additions and renames change it; timestamps do not (works outside git)."""
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")

    def digest() -> str:
        return keys.source_digest(keys._python_files(tmp_path), tmp_path)

    first = digest()
    (tmp_path / "a.py").touch()
    assert digest() == first
    seen = {first}
    for change in (
        lambda: (tmp_path / "sub" / "b.py").write_text("y = 3\n"),
        lambda: (tmp_path / "c.py").write_text(""),
        lambda: (tmp_path / "c.py").rename(tmp_path / "sub" / "c.py"),
    ):
        change()
        assert digest() not in seen
        seen.add(digest())
    assert keys.code_version() == keys.code_version() and len(keys.code_version()) == 64


@pytest.mark.slow
def test_changing_srukf_alpha_reuses_the_baselines_and_the_data(tmp_path, spies):
    """A sweep over the SR-UKF's α: after the first cell only the SR-UKF runs, and the truth is
    never simulated again; a cell seen before runs nothing."""
    cache = tmp_path / "cache"
    for alpha in (0.5, 0.1, 1.0, 0.5):
        job.run_job(small_cfg(cache, [f"estimator.srukf.alpha={alpha}"]), tmp_path / str(alpha))
    assert len(spies["builds"]) == 1 and len(spies["pcrlb"]) == 1  # the PCRLB depends on the data alone
    assert spies["runs"] == ["ekf", "ukf", "srukf", "srukf", "srukf"]
    table = pd.read_csv(tmp_path / "1.0" / "metrics.csv")
    assert table.groupby("estimator")["from_cache"].all().to_dict() == {"ekf": True, "srukf": False, "ukf": True}


def test_a_job_killed_halfway_recomputes_only_what_is_missing(tmp_path, spies, monkeypatch):
    """Each result is stored as soon as it is done: killed during the third estimator, the job
    restarted runs only that one."""
    cfg = small_cfg(tmp_path / "cache")
    counted_run = estimator_runs.run_estimator

    def killed_at_srukf(name, *args, **kwargs):
        if name == "srukf":
            raise KeyboardInterrupt  # not an Exception: it ends the job as a kill would
        return counted_run(name, *args, **kwargs)

    monkeypatch.setattr(estimator_runs, "run_estimator", killed_at_srukf)
    with pytest.raises(KeyboardInterrupt):
        job.run_job(cfg, tmp_path / "killed")
    monkeypatch.setattr(estimator_runs, "run_estimator", counted_run)
    spies["builds"].clear()
    spies["runs"].clear()
    job.run_job(cfg, tmp_path / "again")
    assert spies["builds"] == [] and spies["runs"] == ["srukf"]


def test_a_disabled_cache_never_touches_its_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("QUADEST_CACHE_DIR", str(tmp_path / "from_env"))
    job.run_job(small_cfg(tmp_path / "from_config", ["cache.enabled=false"]), tmp_path / "a")
    job.run_job(compose_config([*SMALL, "cache.enabled=false"]), tmp_path / "b")
    assert not (tmp_path / "from_config").exists() and not (tmp_path / "from_env").exists()
    assert (tmp_path / "a" / "metrics.csv").is_file()


WRITER = """
import sys
import numpy as np
from quadest.cache.store import MAGIC, CacheStore
value = {"array": np.arange(2_000_000, dtype=float), "tag": sys.argv[2]}
for _ in range(15):
    CacheStore(__import__("pathlib").Path(sys.argv[1])).put("data", "k" * 64, value)
"""


@pytest.mark.slow
def test_two_processes_writing_the_same_key_leave_a_valid_entry(tmp_path, capsys):
    """Two writers of one 16 MB entry and a reader polling it all the while: every read is a miss
    before the first write and a whole entry afterwards, never a partial file."""
    store = CacheStore(tmp_path)
    writers = [subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path), tag]) for tag in ("a", "b")]
    reads = []
    while any(w.poll() is None for w in writers):
        reads.append(store.get("data", "k" * 64))
    assert [w.returncode for w in writers] == [0, 0]
    hits = [i for i, r in enumerate(reads) if r is not None]
    assert hits and hits == list(range(hits[0], len(reads)))  # read while written, and never partial
    seen = [reads[i] for i in hits]
    final = store.get("data", "k" * 64)
    np.testing.assert_array_equal(final["array"], np.arange(2_000_000, dtype=float))
    assert final["tag"] in ("a", "b")
    assert all(r["tag"] in ("a", "b") and r["array"][-1] == 1_999_999 for r in seen)
    assert store.temporary_files() == [] and len(store.entries("data")) == 1
    assert "warning" not in capsys.readouterr().err


def test_clear_empties_the_cache_and_nothing_else(tmp_path, capsys):
    job.run_job(small_cfg(tmp_path, ["estimator=[srukf]"]), tmp_path / "job")
    store = CacheStore(tmp_path)
    assert len(store.entries("data")) == 2 and len(store.entries("estimator")) == 1  # data and its PCRLB
    (tmp_path / "estimator" / ".tmp-killed-writer.pkl").write_bytes(b"partial")
    (tmp_path / "notes.txt").write_text("not the cache's")
    assert cache_main(["info", "--dir", str(tmp_path)]) == 0
    assert "temporary: 1 files" in capsys.readouterr().out
    assert cache_main(["clear", "--dir", str(tmp_path)]) == 0
    assert "Deleted 4 files" in capsys.readouterr().out
    assert store.entries("data") == store.entries("estimator") == store.temporary_files() == []
    assert (tmp_path / "notes.txt").read_text() == "not the cache's"
    assert cache_main(["info", "--dir", str(tmp_path)]) == 0
    assert "0 entries" in capsys.readouterr().out


def framed(payload: bytes) -> bytes:
    """A file with a valid header and checksum around ``payload``."""
    return MAGIC + hashlib.blake2b(payload, digest_size=32).digest() + payload


@pytest.mark.parametrize(
    "damage",
    [
        lambda blob: blob[: len(blob) // 2],  # truncated
        lambda blob: (
            blob[: len(blob) // 2] + bytes(b ^ 0xFF for b in blob[len(blob) // 2 :][:8]) + blob[len(blob) // 2 + 8 :]
        ),
        lambda blob: b"not a cache file",
        lambda blob: b"",
        lambda blob: framed(b"a whole file, but not a pickle"),
        lambda blob: framed(pickle.dumps({"key": "another key", "value": 0})),
    ],
    ids=["truncated", "flipped", "foreign", "empty", "unpicklable", "other-key"],
)
@pytest.mark.slow
def test_a_damaged_entry_is_a_miss_and_is_replaced(tmp_path, spies, capsys, damage):
    cache = tmp_path / "cache"
    cfg = small_cfg(cache, ["estimator=[ekf,srukf]"])
    job.run_job(cfg, tmp_path / "first")
    store = CacheStore(cache)
    for path in [*store.entries("data"), *store.entries("estimator")]:
        path.write_bytes(damage(path.read_bytes()))
    for calls in spies.values():
        calls.clear()
    job.run_job(cfg, tmp_path / "second")
    assert len(spies["builds"]) == len(spies["pcrlb"]) == 1 and spies["runs"] == ["ekf", "srukf"]
    assert capsys.readouterr().err.count("recomputing it") == 4  # data, its PCRLB and two results
    first = pd.read_csv(tmp_path / "first" / "metrics.csv").drop(columns=TIMING)
    second = pd.read_csv(tmp_path / "second" / "metrics.csv").drop(columns=TIMING)
    pd.testing.assert_frame_equal(second, first, check_exact=True)
    job.run_job(cfg, tmp_path / "third")  # the rewritten entries are whole again
    assert len(spies["builds"]) == len(spies["pcrlb"]) == 1 and spies["runs"] == ["ekf", "srukf"]


PLUGIN = "from target_plugin import LinearizedKF\n\n\nclass Plugin(LinearizedKF):\n    pass\n"


@pytest.mark.parametrize("layout", ["module", "package"])
def test_a_plugin_is_keyed_by_its_source(tmp_path, monkeypatch, layout):
    """A plugin's own source (its single module, or every file of its top-level package) is part
    of its key: quadest's code version does not cover it."""
    name = f"cache_plugin_{layout}"
    if layout == "module":
        defining, edited = tmp_path / f"{name}.py", tmp_path / f"{name}.py"
        defining.write_text(PLUGIN)
        path = f"{name}.Plugin"
    else:
        (tmp_path / name).mkdir()
        (tmp_path / name / "__init__.py").write_text("")
        defining, edited = tmp_path / name / "filters.py", tmp_path / name / "tuning.py"
        defining.write_text(PLUGIN)
        edited.write_text("GAIN = 1.0\n")
        path = f"{name}.filters.Plugin"
    monkeypatch.syspath_prepend(str(tmp_path))
    module_name, _, _ = path.rpartition(".")
    cls = __import__(module_name, fromlist=["Plugin"]).Plugin

    def key() -> str | None:
        keys._module_source_digest.cache_clear()  # as a new process would: read the files now
        return keys.estimator_key("d" * 64, "mine", {"_target_": path}, cls, 50.0, 0)

    before = key()
    edited.write_text(edited.read_text() + "# edited\n")
    try:
        assert before is not None and key() != before
    finally:
        keys._module_source_digest.cache_clear()
    from quadest.estimators.srukf import SRUKF

    assert keys.plugin_digest(SRUKF) == ""


def test_a_plugin_without_source_is_never_cached(tmp_path, spies, monkeypatch):
    module = types.ModuleType("sourceless_plugin")
    module.Plugin = type("Plugin", (LinearizedKF,), {"__module__": "sourceless_plugin"})
    monkeypatch.setitem(sys.modules, "sourceless_plugin", module)
    assert keys.plugin_digest(module.Plugin) is None
    cfg = small_cfg(tmp_path / "cache", ["estimator=[srukf]", "+estimator.mine._target_=sourceless_plugin.Plugin"])
    job.run_job(cfg, tmp_path / "a")
    job.run_job(cfg, tmp_path / "b")
    assert spies["runs"] == ["srukf", "mine", "mine"]


@pytest.mark.parametrize("where", ["config", "env"])
def test_a_cache_folder_that_is_a_file_is_refused_with_one_line(tmp_path, monkeypatch, where):
    file = tmp_path / "a_file"
    file.write_text("")
    if where == "env":
        monkeypatch.setenv("QUADEST_CACHE_DIR", str(file))
        cfg = compose_config(SMALL)
    else:
        cfg = small_cfg(file)
    key = "QUADEST_CACHE_DIR" if where == "env" else "cache.dir"
    with pytest.raises(ConfigError, match=rf"^{key}=.*existing file") as info:
        validate(cfg)
    assert "\n" not in str(info.value)
    validate(compose_config([*SMALL, f"cache.dir={file}", "cache.enabled=false"]))  # off: never looked at


def test_bad_cache_values_end_with_one_line_naming_the_key(capsys):
    for override, key in (("cache.enabled=maybe", "cache.enabled"), ("cache.dir=''", "cache.dir")):
        with pytest.raises(SystemExit) as info:
            precheck([override])
        assert info.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and key in err, err


def test_the_test_suite_never_uses_the_users_cache(tmp_path_factory):
    """tests/conftest.py points every test (and the quadest processes it starts, which inherit the
    environment) at a temporary cache."""
    assert default_cache_dir().is_relative_to(tmp_path_factory.getbasetemp())


def test_a_replayed_log_is_keyed_by_its_bytes(tmp_path):
    """The same ``source.path`` with other bytes is other data (a log rewritten in place)."""
    log = tmp_path / "flight.ulg"
    log.write_bytes(b"first flight")
    cfg = compose_config(["experiment=px4_replay", f"source.path={log}"])
    first = data_key(cfg)
    log.write_bytes(b"second flight")
    assert data_key(cfg) != first
    log.write_bytes(b"first flight")
    assert data_key(cfg) == first
