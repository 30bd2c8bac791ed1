"""Square-root helpers of the thesis SR-UKF (seed 000, §5.2.3), batched over Monte Carlo runs.

Every function takes arrays with a leading batch axis ``B``; factors are lower triangular with a
positive diagonal, so that ``P = S @ S.T`` for each run.

- :func:`qr_factor` is the thesis's ``qr{·}``: the lower Cholesky factor of ``A Aᵀ`` from a QR
  decomposition of ``Aᵀ``, with the signs of the diagonal made positive.
- :func:`cholupdate` is ``cholupdate{S, u, ±ν}``: the factor of ``S Sᵀ ± ν u uᵀ``, O(n²) per
  vector, applied column by column for a matrix ``u``. A downdate that would make the matrix
  indefinite raises :class:`~quadest.errors.DowndateError` naming the failed runs.
- :func:`kalman_gain` is eq. 5.26: ``K = (Pxy / Syᵀ) / Sy``, two triangular solves.

Two backends compute them. The ``*_numpy`` functions below are the readable references, batched
numpy with the equation tags. The compiled kernels of :mod:`quadest.numerics.compiled` (numba) do
the same arithmetic one small matrix at a time, which at B = 1000 is several times faster than
numpy's per-call overhead allows. The public functions use the compiled kernels when numba imports
and the environment variable ``QUADEST_KERNELS`` is ``numba`` (the default) and the numpy
references when it is ``numpy`` (docs/benchmarks.md). Both agree to round-off (tests/test_kernels.py).
"""

from __future__ import annotations

import os
from functools import cache
from types import ModuleType

import numpy as np

from quadest.errors import ConfigError, DowndateError

KERNELS_ENV = "QUADEST_KERNELS"
DOWNDATE_FAILED = "Cholesky downdate would make the covariance indefinite"
KERNEL_BACKENDS = ("numba", "numpy")


@cache
def _compiled() -> ModuleType | None:
    """The compiled kernels, or ``None`` when numba cannot be imported."""
    try:
        from quadest.numerics import compiled
    except ImportError:
        return None
    return compiled


def requested_kernels() -> str:
    """``$QUADEST_KERNELS``, ``numba`` when unset; checked without importing numba.

    Raises:
        ConfigError: for a value other than ``numba`` or ``numpy``.
    """
    value = os.environ.get(KERNELS_ENV, "numba")
    if value not in KERNEL_BACKENDS:
        raise ConfigError(KERNELS_ENV, value, f"allowed values are {', '.join(KERNEL_BACKENDS)}")
    return value


def kernel_backend() -> str:
    """The backend of the square-root numerics: :func:`requested_kernels`, or ``numpy`` when numba
    is asked for but cannot be imported."""
    value = requested_kernels()
    if value == "numba" and _compiled() is None:
        return "numpy"
    return value


def _kernels() -> ModuleType | None:
    """The compiled kernels when the backend is ``numba``, else ``None``."""
    return _compiled() if kernel_backend() == "numba" else None


def warm_up(model: object | None = None) -> None:
    """Load the compiled kernels now (from numba's on-disk cache, compiling them if it is empty),
    so that no timed filter step pays for it: numba's first call in a process also initialises its
    compiler (docs/benchmarks.md gives the times). Also the model's compiled ``f``/``h``, for a
    model that has them (``model.warm_up_kernels()``). Nothing happens on the numpy backend."""
    if _kernels() is None:
        return
    _load_square_root_kernels()
    if hasattr(model, "warm_up_kernels"):
        model.warm_up_kernels()


@cache
def _load_square_root_kernels() -> None:
    """One call of each square-root kernel, and of the SR-UKF's fused steps
    (:mod:`quadest.numerics.unscented`), on a batch of one 1 × 1 factor (same types as any call)."""
    S = np.ones((1, 1, 1))
    qr_factor(S)
    cholupdate(S, S, 1.0)
    kalman_gain(S, S)
    whiten(S, S[:, 0])
    kernels, x, X, w, failed = _compiled(), np.ones((1, 1)), np.ones((1, 3, 1)), np.ones(3), np.zeros(1, dtype=bool)
    kernels.unscented_points_kernel(x, S, 1.0, X)
    kernels.unscented_moments_kernel(X, w, 1.0, 1.0, True, S[0], x.copy(), S.copy(), failed)
    kernels.unscented_correction_kernel(X, x, X, x, w, S, S, x, x.copy(), S.copy(), x.copy(), failed)


def _as_batch(a: np.ndarray, core: int) -> np.ndarray:
    """``a`` as a C-contiguous float64 array with one leading batch axis before ``core`` axes."""
    return np.ascontiguousarray(a, dtype=float).reshape((-1, *a.shape[a.ndim - core :]))


def qr_factor(A: np.ndarray) -> np.ndarray:
    """Lower-triangular factor ``S`` with positive diagonal such that ``S Sᵀ = A Aᵀ`` (the thesis's
    ``qr{A}``, eqs 5.18, 5.23), for ``A`` of shape (…, n, L) with L ≥ n; see :func:`qr_factor_numpy`."""
    kernels = _kernels()
    A = np.asarray(A, dtype=float)
    if kernels is None or A.ndim < 2 or A.size == 0:
        return qr_factor_numpy(A)
    n, L = A.shape[-2:]
    if L < n:
        raise ValueError(f"qr_factor needs at least as many columns as rows, got A of shape {A.shape}")
    out = np.empty((*A.shape[:-1], n))
    kernels.qr_factor_kernel(_as_batch(A, 2), out.reshape(-1, n, n))
    return out


def cholupdate(S: np.ndarray, u: np.ndarray, nu: float) -> np.ndarray:
    """Cholesky factor of ``S Sᵀ + ν u uᵀ`` (eqs 5.19, 5.24, 5.29); see :func:`cholupdate_numpy`
    for the shapes and the :class:`~quadest.errors.DowndateError` raised for failed runs."""
    kernels = _kernels()
    S = np.asarray(S, dtype=float)
    if kernels is None or S.ndim != 3 or S.size == 0:
        return cholupdate_numpy(S, u, nu)
    x = np.asarray(u, dtype=float)
    if x.ndim == S.ndim - 1:
        x = x[..., None]
    if x.shape[:-1] != S.shape[:-1]:
        raise ValueError(f"cholupdate: u of shape {np.shape(u)} does not fit S of shape {S.shape}")
    S = np.ascontiguousarray(S)
    out = np.empty_like(S)
    failed = np.zeros(S.shape[0], dtype=bool)
    kernels.cholupdate_kernel(S, np.ascontiguousarray(x), float(np.sqrt(abs(nu))), bool(nu < 0), out, failed)
    if failed.any():
        _raise_downdate_error(out, failed)
    return out


def kalman_gain(Pxy: np.ndarray, Sy: np.ndarray) -> np.ndarray:
    """Kalman gain ``K = Pxy (Sy Syᵀ)⁻¹`` by two triangular solves (eq. 5.26); see :func:`kalman_gain_numpy`."""
    kernels = _kernels()
    Pxy, Sy = np.asarray(Pxy, dtype=float), np.asarray(Sy, dtype=float)
    if kernels is None or Pxy.ndim != 3 or Sy.shape != (Pxy.shape[0], Pxy.shape[2], Pxy.shape[2]):
        return kalman_gain_numpy(Pxy, Sy)
    K = np.empty_like(Pxy, order="C")
    kernels.kalman_gain_kernel(np.ascontiguousarray(Pxy), np.ascontiguousarray(Sy), K)
    return K


def whiten(S: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``S⁻¹ r`` for lower-triangular ``S`` (B, m, m) and vectors ``r`` (B, m); see :func:`whiten_numpy`."""
    kernels = _kernels()
    S, r = np.asarray(S, dtype=float), np.asarray(r, dtype=float)
    if kernels is None or r.ndim != 2 or S.shape != (*r.shape, r.shape[1]):
        return whiten_numpy(S, r)
    out = np.empty_like(r, order="C")
    kernels.whiten_kernel(np.ascontiguousarray(S), np.ascontiguousarray(r), out)
    return out


def _raise_downdate_error(result: np.ndarray, failed: np.ndarray) -> None:
    err = DowndateError(DOWNDATE_FAILED, np.flatnonzero(failed))
    err.result = result
    raise err


def qr_factor_numpy(A: np.ndarray) -> np.ndarray:
    """Lower-triangular factor ``S`` with positive diagonal such that ``S Sᵀ = A Aᵀ`` (numpy reference).

    ``A`` has shape (B, n, L) with L ≥ n. The thesis writes this ``qr{A}`` (eqs 5.18, 5.23):
    factorise ``Aᵀ = Q R``; then ``A Aᵀ = Rᵀ R``. NumPy's ``R`` may carry negative diagonal
    entries, which :func:`cholupdate` cannot use, so each row of ``R`` is multiplied by the sign
    of its diagonal element (``Rᵀ R`` is unchanged by that).
    """
    A = np.asarray(A, dtype=float)
    n, L = A.shape[-2:]
    if L < n:
        raise ValueError(f"qr_factor needs at least as many columns as rows, got A of shape {A.shape}")
    R = np.linalg.qr(np.swapaxes(A, -1, -2), mode="r")
    signs = np.sign(np.diagonal(R, axis1=-2, axis2=-1))
    signs = np.where(signs == 0.0, 1.0, signs)
    return np.swapaxes(R * signs[..., :, None], -1, -2)


def cholupdate_numpy(S: np.ndarray, u: np.ndarray, nu: float) -> np.ndarray:
    """Cholesky factor of ``S Sᵀ + ν u uᵀ``, an update for ν > 0, a downdate for ν < 0 (numpy reference).

    Shapes: ``S`` (B, n, n) lower triangular with a positive diagonal; ``u`` (B, n) for a rank-one
    change or (B, n, k) for ``k`` sequential rank-one changes, one per column (eq. 5.29). The input
    arrays are not modified.

    Raises:
        DowndateError: when a downdate would leave a non-positive pivot in some runs. The error's
            ``runs`` names them; ``result`` holds the factor computed for every run, with the
            input factor in place of each failed run's, so a batched filter can flag the failed
            runs and continue with the others.
    """
    S = np.asarray(S, dtype=float)
    x = np.asarray(u, dtype=float)
    if x.ndim == S.ndim - 1:
        x = x[..., None]
    if x.shape[:-1] != S.shape[:-1]:
        raise ValueError(f"cholupdate: u of shape {np.shape(u)} does not fit S of shape {S.shape}")
    # Work batch-last, (n, n, B) and (n, k, B), so that every slice below is contiguous. The
    # sub-column arithmetic writes in place (``out=``): the same operations in the same order as
    # ``col = (L + σ s v) / c; v = c v − s col``, without temporaries (bit-identical results).
    L = np.array(np.moveaxis(S, (-2, -1), (0, 1)), order="C", copy=True)
    x = np.moveaxis(x, (-2, -1), (0, 1)) * np.sqrt(abs(nu))
    downdate = nu < 0
    n = L.shape[0]
    if n == 0:  # an empty factor (a model without a primary measurement) has nothing to change
        return S.copy()
    scratch = np.empty_like(L[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        for j in range(x.shape[1]):
            v = np.array(x[:, j])
            for k in range(n):
                Lkk = L[k, k]
                vk = v[k]
                r2 = Lkk * Lkk
                v2 = vk * vk
                r = np.sqrt(r2 - v2 if downdate else r2 + v2)  # NaN where a downdate fails
                c = r / Lkk
                s = vk / Lkk
                L[k, k] = r
                if k + 1 < n:
                    col, rest, tmp = L[k + 1 :, k], v[k + 1 :], scratch[: n - k - 1]
                    np.multiply(-s if downdate else s, rest, out=tmp)
                    np.add(col, tmp, out=col)
                    np.divide(col, c, out=col)
                    np.multiply(rest, c, out=rest)
                    np.multiply(s, col, out=tmp)
                    np.subtract(rest, tmp, out=rest)
    L = np.moveaxis(L, (0, 1), (-2, -1))
    # A failed pivot (r² ≤ 0) leaves NaN, inf or a zero diagonal in that run's rows only.
    failed = ~(np.diagonal(L, axis1=-2, axis2=-1) > 0.0).all(-1) | ~np.isfinite(L).all((-2, -1))
    if failed.any():
        L = np.array(L)
        L[failed] = S[failed]
        _raise_downdate_error(L, failed)
    return np.ascontiguousarray(L)


def psd_sqrt(C: np.ndarray, name: str = "matrix") -> np.ndarray:
    """Lower-triangular ``L`` with ``L Lᵀ = C`` for a symmetric positive *semi*-definite ``C``
    (thesis §5.2.3 needs only ``√R_v`` with ``R_v ⪰ 0``): Cholesky when ``C`` is definite, otherwise
    the QR factor of ``V √Λ`` from the eigen-decomposition, so a rank-deficient process noise works.

    Raises:
        ValueError: if ``C`` is not symmetric or has an eigenvalue below ``−n·eps·‖C‖`` (indefinite).
    """
    C = np.asarray(C, dtype=float)
    if C.ndim != 2 or C.shape[0] != C.shape[1] or not np.allclose(C, C.T, rtol=1e-12, atol=0.0):
        raise ValueError(f"{name} must be a symmetric square matrix")
    try:
        return np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        vals, vecs = np.linalg.eigh(C)
        tol = C.shape[0] * np.finfo(float).eps * max(np.abs(vals).max(), np.finfo(float).tiny)
        if vals.min() < -tol:
            raise ValueError(f"{name} must be positive semi-definite (smallest eigenvalue {vals.min():.3g})") from None
        return qr_factor((vecs * np.sqrt(np.clip(vals, 0.0, None)))[None])[0]


def batched_cholesky(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower Cholesky factors of a batch (B, n, n) and a mask of the runs that are not positive
    definite (their factor is NaN). One LAPACK sweep when every run is fine."""
    try:
        return np.linalg.cholesky(P), np.zeros(P.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        out = np.full_like(P, np.nan)
        failed = np.zeros(P.shape[0], dtype=bool)
        for i in range(P.shape[0]):
            try:
                out[i] = np.linalg.cholesky(P[i])
            except np.linalg.LinAlgError:
                failed[i] = True
        return out, failed


def _solve_lower(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Forward substitution ``L y = b`` for lower-triangular ``L`` (B, m, m), ``b`` (B, m, k)."""
    y = np.empty(np.broadcast_shapes(L.shape[:-2], b.shape[:-2]) + b.shape[-2:])
    for i in range(L.shape[-1]):
        acc = b[..., i, :] - (L[..., i : i + 1, :i] @ y[..., :i, :])[..., 0, :]
        y[..., i, :] = acc / L[..., i, i, None]
    return y


def _solve_upper_transposed(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Back substitution ``Lᵀ y = b`` for lower-triangular ``L`` (B, m, m), ``b`` (B, m, k)."""
    m = L.shape[-1]
    Lt = np.swapaxes(L, -1, -2)
    y = np.empty(np.broadcast_shapes(L.shape[:-2], b.shape[:-2]) + b.shape[-2:])
    for i in range(m - 1, -1, -1):
        acc = b[..., i, :] - (Lt[..., i : i + 1, i + 1 :] @ y[..., i + 1 :, :])[..., 0, :]
        y[..., i, :] = acc / L[..., i, i, None]
    return y


def kalman_gain_numpy(Pxy: np.ndarray, Sy: np.ndarray) -> np.ndarray:
    """Kalman gain ``K = Pxy (Sy Syᵀ)⁻¹`` by two triangular solves (thesis eq. 5.26; numpy reference).

    ``Pxy`` is (B, n, m) and ``Sy`` the lower factor (B, m, m) of the innovation covariance.
    ``K Sy Syᵀ = Pxy`` is solved as ``Sy A = Pxyᵀ`` (forward) then ``Syᵀ Kᵀ = A`` (backward);
    no matrix is inverted.
    """
    A = _solve_lower(Sy, np.swapaxes(Pxy, -1, -2))
    return np.swapaxes(_solve_upper_transposed(Sy, A), -1, -2)


def whiten_numpy(S: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``S⁻¹ r`` for lower-triangular ``S`` (B, m, m) and vectors ``r`` (B, m) (numpy reference).

    ``|S⁻¹ r|²`` is the Mahalanobis form ``rᵀ (S Sᵀ)⁻¹ r`` used for NEES and NIS.
    """
    return _solve_lower(S, r[..., None])[..., 0]
