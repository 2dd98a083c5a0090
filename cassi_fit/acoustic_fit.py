"""Acoustic calibration: a speaker's vocal-tract parameters fitted to the measured formants.

The unknowns are :class:`~cassi_fit.area_function.TractParams`: the larynx's drop below the
hyoid (the vocal tract's length, which sets every formant's scale and which no pellet
sees), the area rule's overall scale, the pharynx's scale (the pharynx's width across and
its depth behind the tongue root, which no pellet reaches: the model's tongue root is not
the speaker's) and the lips' scale (the lip opening's width across, which midsagittal
pellets do not measure). The tongue, jaw and lips stay where the pellets put them: the
frames' vertices are fixed, so the pellets' fit is kept exactly. The area rule's published
coefficients are never refitted: only these four scales move.

The fit (optimistix Levenberg-Marquardt) minimises, over the scored frames of the training
vowels, ``log(F_model / F_measured)`` of F1-F3 through the differentiable chain (area
function, tube, formants by implicit differentiation), with a weak prior keeping the
parameters near the adult norms (``PRIOR_SD``): the drop within about 10 mm of 30 mm, the
scales within about a factor e^0.5. Scored by leaving one vowel quality out
(:func:`leave_one_quality_out`); a recording with one vowel quality has no held-out
figure (say so).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import area_function as af
from . import tube

PRIOR_SD = {"larynx_drop_mm": 10.0, "log_scale": 0.5}
MAX_FRAMES = 48  # frames per fit (an even subsample): the fit's cost grows with them
MAX_STEPS = 40
#: The fit's formant search grid (Hz): Newton refines from it to the same formants as the
#: finer default grid wherever the formants are over 2 steps apart, at a fifth of the cost.
FIT_GRID_STEP_HZ = 40.0


class AcousticFit(NamedTuple):
    """The fitted ``tract``, whether the solver ``converged``, its ``steps`` and the
    training frames' median relative F1-F3 error before and after."""

    tract: af.TractParams
    converged: bool
    steps: int
    before: np.ndarray
    after: np.ndarray


def _unpack(x, base: af.TractParams):
    return af.TractParams(base.larynx_drop_mm + x[0], base.area_scale * jnp.exp(x[1]),
                          base.pharynx_scale * jnp.exp(x[2]), base.lip_scale * jnp.exp(x[3]))


def _subsample(index: np.ndarray, n: int) -> np.ndarray:
    if len(index) <= n:
        return index
    return index[np.round(np.linspace(0, len(index) - 1, n)).astype(int)]


def fit_tract(geometry: af.TractGeometry, vertices, measured: np.ndarray, scale: float, *,
              base: af.TractParams | None = None, max_frames: int = MAX_FRAMES) -> AcousticFit:
    """Fit :class:`TractParams` to ``measured (m, 3)`` Hz formants of the frames
    ``vertices (m, V, 3)`` (module docstring). ``base``: the prior's centre (default the
    adult norms)."""
    vertices = jnp.asarray(vertices)
    dtype = vertices.dtype
    base = af.default_tract(dtype) if base is None else base
    pick = _subsample(np.arange(len(measured)), max_frames)
    v = vertices[pick]
    target = jnp.log(jnp.asarray(measured[pick], dtype))
    sd = jnp.asarray([PRIOR_SD["larynx_drop_mm"]] + [PRIOR_SD["log_scale"]] * 3, dtype)
    n = len(pick)

    def residuals(x, args):
        tract = _unpack(x, base)
        areas, lengths, _ = af.area_functions(geometry, v, tract, scale)
        f = jax.vmap(lambda a, ln: tube.formants(a, ln, grid_step_hz=FIT_GRID_STEP_HZ))(
            areas, lengths).frequency[:, :3]
        misfit = (jnp.log(f) - target).reshape(-1)
        # a missing model formant (NaN) is a large misfit, not a NaN step
        misfit = jnp.where(jnp.isfinite(misfit), misfit, 1.0)
        return jnp.concatenate([misfit / jnp.sqrt(n), x / sd / jnp.sqrt(3.0 * n) * 0.1])

    solver = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-6)
    x0 = jnp.zeros(4, dtype)
    sol = optx.least_squares(residuals, solver, x0, max_steps=MAX_STEPS, throw=False)
    tract = _unpack(sol.value, base)
    before = _median_error(geometry, v, base, scale, measured[pick])
    after = _median_error(geometry, v, tract, scale, measured[pick])
    return AcousticFit(tract, bool(sol.result == optx.RESULTS.successful),
                       int(sol.stats["num_steps"]), before, after)


def _median_error(geometry, vertices, tract, scale, measured) -> np.ndarray:
    areas, lengths, _ = af.area_functions(geometry, vertices, tract, scale)
    f = np.asarray(tube.formants_batch(areas, lengths).frequency[:, :3])
    return np.nanmedian(np.abs(f / measured - 1.0), axis=0)


def vowel_quality(label: str) -> str:
    """A vowel label's quality: the label without length marks and stress digits."""
    return label.strip().replace(":", "").rstrip("012")


def leave_one_quality_out(result, *, max_frames: int = MAX_FRAMES):
    """For each vowel quality of ``result`` (an :class:`~cassi_fit.acoustics.Acoustics`)
    with scored frames: the tract fitted to the other qualities' scored frames and the
    model's F1-F3 on this quality's frames with it. Returns ``(held_out (m, 3) Hz, NaN for
    frames not scored or of a quality that could not be held out; fits {quality:
    AcousticFit})``, or ``(None, {})`` with fewer than two qualities (no held-out figure)."""
    scored = result.scored
    quality = np.array([vowel_quality(str(s)) for s in result.labels])
    qualities = sorted(set(quality[scored]))
    held = np.full((len(result.times), 3), np.nan)
    if len(qualities) < 2:
        return None, {}
    fits = {}
    geometry, vertices, scale = result.geometry, result.vertices, result.scale
    for q in qualities:
        train = np.nonzero(scored & (quality != q))[0]
        test = np.nonzero(scored & (quality == q))[0]
        fit = fit_tract(geometry, vertices[train], result.measured.frequency[train], scale,
                        max_frames=max_frames)
        fits[q] = fit
        areas, lengths, _ = af.area_functions(geometry, jnp.asarray(vertices)[test], fit.tract, scale)
        held[test] = np.asarray(tube.formants_batch(areas, lengths).frequency)[:, :3]
    return held, fits


def tract_record(tract: af.TractParams) -> dict[str, float]:
    """The fitted parameters as plain numbers (for a calibration file or a table)."""
    return {k: float(getattr(tract, k)) for k in ("larynx_drop_mm", "area_scale",
                                                  "pharynx_scale", "lip_scale")}


def tract_from_record(record: dict) -> af.TractParams:
    """:class:`TractParams` from :func:`tract_record`'s numbers."""
    return af.TractParams(*(jnp.asarray(float(record[k])) for k in (
        "larynx_drop_mm", "area_scale", "pharynx_scale", "lip_scale")))

