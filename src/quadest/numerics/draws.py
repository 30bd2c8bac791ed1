"""Random draws batched over Monte Carlo runs, each run from its own generator.

Run ``b`` of a batch draws from ``rngs[b]`` exactly what it draws alone (common random numbers,
and a batch equals each run alone). :func:`standard_normals` is the one entry point: on the numba
backend (``QUADEST_KERNELS``, docs/benchmarks.md) it fills the whole batch in one compiled call
(:func:`quadest.numerics.particle_kernels.standard_normal_kernel`), on the numpy backend it loops
over the runs; both give the same numbers, bit for bit, and leave the generators in the same state.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from functools import cache
from types import ModuleType
from typing import Any

import numpy as np

from quadest.numerics.square_root import kernel_backend

_TYPED_LISTS: OrderedDict[tuple[int, ...], tuple[tuple[np.random.Generator, ...], Any]] = OrderedDict()
_TYPED_LISTS_KEPT = 8


@cache
def _particle_kernels() -> ModuleType | None:
    try:
        from quadest.numerics import particle_kernels
    except ImportError:
        return None
    return particle_kernels


def particle_kernels() -> ModuleType | None:
    """The compiled particle kernels on the numba backend, else ``None``."""
    return _particle_kernels() if kernel_backend() == "numba" else None


@cache
def warm_up_particle_kernels() -> None:
    """Load every particle kernel now (from numba's on-disk cache, compiling it if the cache is
    empty), with arguments of the types the filters pass, and build a first ``numba.typed.List``
    of generators (its methods are compiled in every process: about 0.5 s), so that neither the
    runner's timed ``initialize`` nor its first step pays for it. Nothing happens on the numpy
    backend."""
    kernels = particle_kernels()
    if kernels is None:
        return
    rngs, runs = [np.random.default_rng(0)], np.zeros(1, dtype=np.intp)
    kernels.standard_normal_kernel(generator_list(rngs), runs, np.empty((1, 2)))
    w, u, idx = np.full((1, 2), 0.5), np.zeros((1, 2)), np.empty((1, 2), dtype=np.intp)
    for scheme in (kernels.MULTINOMIAL, kernels.SYSTEMATIC, kernels.STRATIFIED, kernels.RESIDUAL):
        kernels.resample_kernel(scheme, w, u, idx)
    x = np.zeros((1, 2, 1))
    kernels.gather_kernel(x, runs, idx, x)
    kernels.gather_kernel(x, runs, idx, np.empty_like(x))
    kernels.gaussian_logpdf_diagonal_kernel(np.zeros((2, 1)), np.ones(1), 1.0, 0.0, np.empty(2))
    shifted, vanished, ess = np.empty((1, 2)), np.empty(1, dtype=bool), np.empty(1)
    kernels.shift_log_weights_kernel(np.zeros((1, 2)), np.zeros((1, 2)), shifted, vanished)
    kernels.normalise_kernel(np.ones((1, 2)), np.empty(2), ess)


def generator_list(rngs: Sequence[np.random.Generator]) -> Any:
    """``rngs`` as the ``numba.typed.List`` the kernels take, built once per sequence of
    generators (building one costs ~0.3 ms per 50 generators, too much for every step). The
    last few lists are kept, each with the generators it points to, so none is freed under it."""
    key = tuple(map(id, rngs))
    if key in _TYPED_LISTS:
        _TYPED_LISTS.move_to_end(key)
        return _TYPED_LISTS[key][1]
    from numba.typed import List

    typed = List(rngs)
    _TYPED_LISTS[key] = (tuple(rngs), typed)
    if len(_TYPED_LISTS) > _TYPED_LISTS_KEPT:
        _TYPED_LISTS.popitem(last=False)
    return typed


def all_runs(rngs: Sequence[np.random.Generator], runs: np.ndarray | None) -> np.ndarray:
    """``runs`` as an index array, every run of ``rngs`` when ``None``."""
    return np.arange(len(rngs)) if runs is None else np.asarray(runs, dtype=np.intp)


def standard_normals(
    rngs: Sequence[np.random.Generator], shape: tuple[int, ...], runs: np.ndarray | None = None
) -> np.ndarray:
    """Standard normals ``(R, *shape)``: row ``r`` is ``rngs[runs[r]].standard_normal(shape)``
    (``runs``: every run when ``None``)."""
    runs = all_runs(rngs, runs)
    out = np.empty((runs.size, int(np.prod(shape))))
    kernels = particle_kernels()
    if kernels is None:
        for row, b in zip(out, runs, strict=True):
            rngs[b].standard_normal(out=row)
    else:
        kernels.standard_normal_kernel(generator_list(rngs), runs, out)
    return out.reshape(runs.size, *shape)
