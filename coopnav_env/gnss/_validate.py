"""Private input checks shared by the ``coopnav_env.gnss`` modules.

Every check returns a float (or int/bool) ``numpy`` array view of its input
(no copy unless a dtype conversion is needed) and raises ``ValueError`` naming
the offending argument and value. None of them modifies its input.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def _describe(value: NDArray) -> str:
    """Short text form of ``value`` for error messages."""
    return np.array2string(np.asarray(value), threshold=6, edgeitems=2)


def as_float_array(value: ArrayLike, name: str, *, allow_nan: bool = False) -> NDArray[np.float64]:
    """Convert ``value`` to a float array, rejecting non-finite entries.

    Parameters
    ----------
    value : array_like
        Any numeric array.
    name : str
        Argument name used in the error message.
    allow_nan : bool, optional
        If true, NaN entries are accepted (infinities still are not).

    Returns
    -------
    ndarray
        ``value`` as ``float64``.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if np.any(bad):
        raise ValueError(f"{name} must be finite, got {_describe(arr)}")
    return arr


def as_points(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Finite float array of shape ``(..., 3)``."""
    arr = as_float_array(value, name)
    if arr.ndim < 1 or arr.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3), got shape {arr.shape}")
    return arr


def as_point_list(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Finite float array of shape ``(n, 3)``."""
    arr = as_float_array(value, name)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got shape {arr.shape}")
    return arr


def as_latitude_deg(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Finite latitude array in ``[-90, 90]`` degrees."""
    arr = as_float_array(value, name)
    if np.any(np.abs(arr) > 90.0):
        raise ValueError(f"{name} must lie in [-90, 90] deg, got {_describe(arr)}")
    return arr


def as_elevation_deg(value: ArrayLike, name: str) -> NDArray[np.float64]:
    """Finite elevation array in ``[-90, 90]`` degrees."""
    arr = as_float_array(value, name)
    if np.any(np.abs(arr) > 90.0):
        raise ValueError(f"{name} must lie in [-90, 90] deg, got {_describe(arr)}")
    return arr


def as_bool_matrix(value: ArrayLike, name: str, shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """Boolean array of exactly ``shape`` (booleans or 0/1 integers accepted)."""
    arr = np.asarray(value)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if arr.dtype != np.bool_:
        if not np.issubdtype(arr.dtype, np.integer) or np.any((arr != 0) & (arr != 1)):
            raise ValueError(f"{name} must be boolean, got dtype {arr.dtype}")
        arr = arr.astype(np.bool_)
    return arr


def as_index_array(value: ArrayLike, name: str, n_max: int) -> NDArray[np.intp]:
    """1-D integer array with entries in ``[0, n_max)``."""
    arr = np.asarray(value)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must hold integers, got dtype {arr.dtype}")
    arr = arr.astype(np.intp)
    if np.any((arr < 0) | (arr >= n_max)):
        raise ValueError(f"{name} entries must lie in [0, {n_max}), got {_describe(arr)}")
    return arr


def as_nonnegative_scalar(value: float, name: str) -> float:
    """Finite, non-negative Python float."""
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real number >= 0, got {value!r}") from exc
    if not np.isfinite(out) or out < 0.0:
        raise ValueError(f"{name} must be a finite real number >= 0, got {value!r}")
    return out


def as_count(value: int, name: str, minimum: int = 0) -> int:
    """Python int ``>= minimum`` (bools rejected)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def readonly(arr: NDArray) -> NDArray:
    """Private read-only copy of ``arr`` (for frozen dataclass fields)."""
    out = np.array(arr, copy=True)
    out.setflags(write=False)
    return out
