"""Every test runs with a result cache of its own in a temporary folder (``QUADEST_CACHE_DIR``,
inherited by the ``quadest`` subprocesses the tests start): the suite never reads or writes the
user's cache (``~/.cache/quadest``), and no test is served results another test computed.
Module- and session-scoped fixtures share one temporary cache."""

from __future__ import annotations

import itertools
import os

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
