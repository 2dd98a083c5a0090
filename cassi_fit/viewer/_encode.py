"""The compact frame encoding of the one-file viewer: every frame of an animation, small.

A recording's face moves in few ways (the jaw, the lips, the tongue: a dozen parameters),
so its vertex motion is close to a low-dimensional linear space. Per animation:

* the **moving vertices**: those that move by more than ``still_mm`` from the rest mesh in
  any frame (the forehead, eyes, upper teeth and palate never move and are not stored);
* their displacements from rest, one row per frame, ``(m, 3n)``, **PCA-compressed**: the
  mean row plus ``k`` principal components (eigenvectors of a Gram matrix), ``k`` the
  fewest of the ranks tried (1, 2, 3, 4, 6, 9, 13, ..., by bisection) whose
  reconstruction error stays within ``tolerance_mm`` at every vertex of every frame
  (checked on the quantised numbers, not estimated), at most ``max_components``;
* basis rows and coefficients **quantised to int16**, one scale per component.

Every frame is kept (no keyframes, no decimation). The page's script rebuilds a frame as
``rest + mean + sum_k coeff[f, k] * coeff_scale[k] * basis[k] * basis_scale[k]``
(:func:`decode_motion` does the same in numpy, for the tests and for checking). The
achieved error is stored with the data (``max_error_mm``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from jaxtyping import Float

from ..errors import CassiError

STILL_MM = 0.01
TOLERANCE_MM = 0.05
MAX_COMPONENTS = 96
_Q = 32767


def _quantise(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(int16 rows, float32 scale per row): row ~= q * scale."""
    peak = np.abs(rows).max(axis=1, initial=0.0)
    scale = np.where(peak > 0, peak / _Q, 1.0).astype(np.float32)
    q = np.round(rows / scale[:, None]).clip(-_Q, _Q).astype(np.int16)
    return q, scale


def _rebuild(mean, coeff_q, coeff_scale, basis_q, basis_scale) -> np.ndarray:
    coeff = coeff_q.astype(np.float64) * coeff_scale.astype(np.float64)
    basis = basis_q.astype(np.float64) * basis_scale[:, None].astype(np.float64)
    return mean.astype(np.float64) + coeff @ basis


def encode_motion(
    frames: Float[Any, "m v 3"],
    rest: Float[Any, "v 3"],
    *,
    tolerance_mm: float = TOLERANCE_MM,
    still_mm: float = STILL_MM,
    max_components: int = MAX_COMPONENTS,
) -> dict[str, Any]:
    """The encoding of ``frames (m, V, 3)`` mm against ``rest (V, 3)`` (see the module
    docstring): ``{"moving" (n,) uint32, "mean" (3n,) float32, "basis" (k, 3n) int16,
    "basis_scale" (k,) float32, "coeff" (m, k) int16, "coeff_scale" (k,) float32,
    "n_components", "max_error_mm"}``. If ``max_components`` cannot reach
    ``tolerance_mm``, the largest error reached is stored and reported, never hidden."""
    frames = np.asarray(frames, np.float64)
    rest = np.asarray(rest, np.float64)
    if frames.ndim != 3 or frames.shape[1:] != rest.shape or rest.shape[1:] != (3,):
        raise CassiError(f"viewer: frames (m, V, 3) and rest (V, 3), got {frames.shape}, "
                         f"{rest.shape}")  # fmt: skip
    if not np.all(np.isfinite(frames)):
        raise CassiError("viewer: the animation's vertices are not all finite")
    displacement = frames - rest[None]
    moving = np.flatnonzero(np.abs(displacement).max(axis=(0, 2)) > still_mm)
    rows = displacement[:, moving].reshape(len(frames), -1)
    mean = rows.mean(axis=0).astype(np.float32)
    centred = rows - mean
    best = (0, *_quantise(centred[:0]), np.zeros((len(rows), 0), np.int16),
            np.zeros(0, np.float32), float(np.abs(centred).max()) if centred.size else 0.0)
    if best[-1] > tolerance_mm:
        vt = _principal_axes(centred, max_components)
        ranks = _candidate_ranks(len(vt))
        lo, hi = 0, len(ranks) - 1  # the first rank that meets the tolerance: bisection
        best = None
        while lo <= hi:
            mid = (lo + hi) // 2
            trial = _with_rank(ranks[mid], vt, rows, centred, mean)
            if trial[-1] <= tolerance_mm:
                best, hi = trial, mid - 1
            else:
                lo = mid + 1
        if best is None:  # not met even by the most components: say how far
            best = _with_rank(ranks[-1], vt, rows, centred, mean)
    k, basis_q, basis_scale, coeff_q, coeff_scale, max_error = best
    return {"moving": moving.astype(np.uint32), "mean": mean, "basis": basis_q,
            "basis_scale": basis_scale, "coeff": coeff_q, "coeff_scale": coeff_scale,
            "n_components": int(k), "max_error_mm": max_error}  # fmt: skip


def _with_rank(k: int, vt: np.ndarray, rows: np.ndarray, centred: np.ndarray,
               mean: np.ndarray) -> tuple:  # fmt: skip
    """``(k, basis_q, basis_scale, coeff_q, coeff_scale, max error mm)`` with ``k`` axes:
    the coefficients are the least-squares fit to the quantised basis, and the error is that
    of the quantised numbers, as the page rebuilds them."""
    basis_q, basis_scale = _quantise(vt[:k])
    basis = basis_q.astype(np.float64) * basis_scale[:, None].astype(np.float64)
    coeff = np.linalg.solve(basis @ basis.T, basis @ centred.T)  # (k, m)
    quantised, coeff_scale = _quantise(coeff)
    coeff_q = np.ascontiguousarray(quantised.T)
    error = rows - _rebuild(mean, coeff_q, coeff_scale, basis_q, basis_scale)
    return k, basis_q, basis_scale, coeff_q, coeff_scale, float(np.abs(error).max())


def _principal_axes(centred: np.ndarray, limit: int) -> np.ndarray:
    """The first ``limit`` principal axes (rows, unit length, by decreasing variance) of
    the rows of ``centred``, from the eigenvectors of the smaller of its two Gram matrices
    (numpy's SVD of a long (m, 3n) matrix was 15x slower here)."""
    m, d = centred.shape
    if m <= d:
        values, vectors = np.linalg.eigh(centred @ centred.T)
        order = np.argsort(values)[::-1][:limit]
        keep = order[values[order] > values.max() * 1e-12]
        axes = vectors[:, keep].T @ centred
        return axes / np.linalg.norm(axes, axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(centred.T @ centred)
    order = np.argsort(values)[::-1][:limit]
    return vectors[:, order[values[order] > values.max() * 1e-12]].T


def _candidate_ranks(limit: int) -> list[int]:
    """1, 2, 3, 4, 6, 9, 13, ... up to ``limit`` (included)."""
    ranks, k = [1, 2, 3], 4
    while k < limit:
        ranks.append(k)
        k = k + max(1, k // 2)
    return [r for r in ranks if r < limit] + [limit]


def decode_motion(encoded: dict[str, Any], rest: Float[Any, "v 3"]) -> np.ndarray:
    """The frames ``(m, V, 3)`` float64 mm that :func:`encode_motion`'s ``encoded`` holds
    (what the page shows)."""
    rest = np.asarray(rest, np.float64)
    rows = _rebuild(encoded["mean"], encoded["coeff"], encoded["coeff_scale"],
                    encoded["basis"], encoded["basis_scale"])  # fmt: skip
    frames = np.repeat(rest[None], len(rows), axis=0)
    moving = encoded["moving"].astype(np.int64)
    frames[:, moving] += rows.reshape(len(rows), len(moving), 3)
    return frames
