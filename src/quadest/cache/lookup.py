"""The cache as one job uses it: its data, then each estimator's result (every job kind alike:
:mod:`quadest.app.estimator_runs`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from quadest.cache.keys import digest_text, estimator_key
from quadest.cache.location import CacheConf, cache_dir
from quadest.cache.store import CacheStore
from quadest.montecarlo.results import EstimatorResult

T = TypeVar("T")


class JobCache:
    """Look-ups and stores of one job. Disabled (``store`` None), it computes everything and never
    touches the cache folder."""

    def __init__(self, store: CacheStore | None, data_key: str | None) -> None:
        self.store = store
        self.data_key = data_key

    @classmethod
    def for_job(cls, cache: CacheConf, data_key: str | None) -> JobCache:
        """The cache of a job with the (validated) ``cache`` settings, following ``enabled`` and
        ``dir``; ``data_key`` is the key of the job's data (the application layer computes it from
        the resolved config, :func:`quadest.app.settings.data_key`; ``None`` when disabled)."""
        if not cache.enabled:
            return cls(None, None)
        if data_key is None:
            raise ValueError("an enabled cache needs the job's data key")
        return cls(CacheStore(cache_dir(cache)), data_key)

    def data(self, build: Callable[[], T]) -> tuple[T, bool]:
        """The job's data from the cache, or made by ``build`` and stored; and whether it was a hit.
        The data is what the job kind makes before any estimator runs: the Monte Carlo data, or a
        closed loop's shared flight with its recorded data."""
        if self.store is None:
            return build(), False
        data = self.store.get("data", self.data_key)
        if data is not None:
            return data, True
        data = build()
        self.store.put("data", self.data_key, data)
        return data, False

    def derived(self, name: str, compute: Callable[[], Any]) -> Any:
        """A value computed from the job's data alone (``name`` says which, e.g. the PCRLB): from
        the cache, or computed by ``compute`` and stored under the data key and ``name``."""
        if self.store is None:
            return compute()
        key = digest_text({"data": self.data_key, "derived": name})
        value = self.store.get("data", key)
        if value is None:
            value = compute()
            self.store.put("data", key, value)
        return value

    def result_key(
        self, label: str, node: Mapping[str, Any], cls: type, divergence_bound: float, saved_runs: int
    ) -> str | None:
        """Key of estimator ``label``'s result in this job; ``None`` if it is not to be cached."""
        if self.store is None:
            return None
        return estimator_key(self.data_key, label, node, cls, divergence_bound, saved_runs)

    def result(self, key: str | None) -> EstimatorResult | None:
        """The stored result of ``key``, or ``None``."""
        if self.store is None or key is None:
            return None
        return self.store.get("estimator", key)

    def keep(self, key: str | None, result: EstimatorResult) -> None:
        """Store a computed result (as soon as it is done: a job killed later keeps it)."""
        if self.store is not None and key is not None:
            self.store.put("estimator", key, result)
