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
parameters near the speaker's adult norms (``PRIOR_SD``): the drop within about 10 mm of
the norm's (``area_function.LARYNX_DROP_MM``: 30 mm for a man, 15 mm for a woman; the
speaker is the one its acoustics were heard with, ``acoustics.speaker_norms``), the scales
within about a factor e^0.5. Scored by leaving one vowel quality out
(:func:`leave_one_quality_out`); a recording with one vowel quality has no held-out
figure (say so).
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import ArrayLike, Float

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


def _residuals(x, args):
    """The fit's residuals (a module-level function: optimistix compiles it once per
    subject topology and frame count, not once per call)."""
    geometry, v, target, base, sd, scale = args
    n = v.shape[0]
    areas, lengths, _ = af.area_functions(geometry, v, _unpack(x, base), scale)
    f = jax.vmap(lambda a, ln: tube.formants(a, ln, grid_step_hz=FIT_GRID_STEP_HZ))(
        areas, lengths).frequency[:, :3]
    misfit = (jnp.log(f) - target).reshape(-1)
    # a missing model formant (NaN) is a large misfit, not a NaN step
    misfit = jnp.where(jnp.isfinite(misfit), misfit, 1.0)
    return jnp.concatenate([misfit / jnp.sqrt(n), x / sd / jnp.sqrt(3.0 * n) * 0.1])


def _subsample(index: np.ndarray, n: int) -> np.ndarray:
    if len(index) <= n:
        return index
    return index[np.round(np.linspace(0, len(index) - 1, n)).astype(int)]


def fit_tract(geometry: af.TractGeometry, vertices: Float[ArrayLike, "m V 3"],
              measured: Float[np.ndarray, "m 3"], scale: float, *,
              base: af.TractParams | None = None, max_frames: int = MAX_FRAMES) -> AcousticFit:
    """Fit :class:`TractParams` to ``measured (m, 3)`` Hz formants of the frames
    ``vertices (m, V, 3)`` (module docstring). ``base``: the prior's centre (default the
    adult male norms; ``area_function.default_tract(dtype, speaker)`` for a speaker's)."""
    vertices = jnp.asarray(vertices)
    dtype = vertices.dtype
    base = af.default_tract(dtype) if base is None else base
    pick = _subsample(np.arange(len(measured)), max_frames)
    v = vertices[pick]
    target = jnp.log(jnp.asarray(measured[pick], dtype))
    sd = jnp.asarray([PRIOR_SD["larynx_drop_mm"]] + [PRIOR_SD["log_scale"]] * 3, dtype)

    args = (geometry, v, target, base, sd, jnp.asarray(scale, dtype))
    tol = jnp.asarray(SOLVER_TOL, dtype)  # an array: other tolerances compile nothing new
    x, successful, steps, decrement, cost = _solve(
        optx.LevenbergMarquardt(rtol=tol, atol=tol), jnp.zeros(4, dtype), args)
    tract = _unpack(x, base)
    before = _median_error(geometry, v, base, scale, measured[pick])
    after = _median_error(geometry, v, tract, scale, measured[pick])
    stationary = float(decrement) <= STATIONARY_DECREMENT * (1.0 + 2.0 * float(cost))
    return AcousticFit(tract, bool(successful) and stationary, int(steps), before, after)


#: The solver's relative and absolute step tolerance: parameters in mm and log-scales, a
#: thousandth is far below what the formants resolve (and above float32's noise in them,
#: so a float32 fit can meet it).
SOLVER_TOL = 1e-3
#: Converged means the solver stopped (its steps became small) *and* the answer is
#: stationary: a Gauss-Newton step from it predicts lowering the cost (half the mean
#: squared log misfit of F1-F3) by at most this, relative to ``1 + 2 cost`` (the jaw's
#: structured solver's form of the rule). The steps also become small where rejected
#: steps shrink the trust region at a kink of the area function or of the formants, away
#: from any minimum: on mo1 two of eleven held-out fits stopped so with 8e-3 still
#: predicted (the larynx left near the norm's), the nine others at 3e-6 to 2.5e-4; a
#: restart from there takes no step. The bound (set after seeing those): at mo1's cost
#: (about 0.05) a gain of about 1 % of the rms formant misfit, where the two stopped fits
#: still predicted about 7 %.
STATIONARY_DECREMENT = 1e-3


@eqx.filter_jit
def _solve(solver, x0, args):
    """``(x, successful, steps, decrement, cost)``: the least-squares fit by ``solver`` from
    ``x0`` and, at its answer, the cost and the Gauss-Newton decrement ``g^T (J^T J)^-1 g``
    (the reduction a full Gauss-Newton step predicts) from the solver's own Jacobian there."""
    sol = optx.least_squares(_residuals, solver, x0, args=args, max_steps=MAX_STEPS, throw=False)
    info = sol.state.f_info
    jac = info.jac.as_matrix()
    grad = jac.T @ info.residual
    normal = jac.T @ jac + 1e-12 * jnp.max(jnp.abs(jac)) ** 2 * jnp.eye(x0.shape[0], dtype=x0.dtype)
    decrement = grad @ jnp.linalg.solve(normal, grad)
    return (sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"], decrement,
            0.5 * jnp.sum(info.residual**2))


@jax.jit
def _compiled_tract_areas(geometry: af.TractGeometry, vertices, tract: af.TractParams, scale):
    return af.area_functions(geometry, vertices, tract, scale)[:2]


def _tract_areas(geometry: af.TractGeometry, vertices, tract: af.TractParams, scale):
    """``(areas, lengths)`` ``(m, n)`` of the frames ``vertices (m, V, 3)``, compiled once
    per frame count and model topology: the geometry is an argument (every subject of the
    topology shares it) and the tract's weakly typed numbers (Python floats,
    ``jnp.asarray(40.0)``) are given the frames' dtype, as arithmetic with the frames would
    give them, so that they compile nothing of their own."""
    vertices = jnp.asarray(vertices)
    dtype = vertices.dtype
    tract = jax.tree.map(lambda a: jnp.asarray(a, dtype) if isinstance(a, (int, float)) or getattr(
        a, "weak_type", False) else a, tract)
    return _compiled_tract_areas(geometry, vertices, tract, jnp.asarray(scale, dtype))


def tract_formants(geometry: af.TractGeometry, vertices, tract: af.TractParams, scale):
    """F1-F4 ``(m, 4)`` Hz of the frames ``vertices (m, V, 3)`` with ``tract`` (compiled:
    the area functions, then ``tube.formants_batch``, the formants every other caller
    compiles for that many frames)."""
    return tube.formants_batch(*_tract_areas(geometry, vertices, tract, scale)).frequency


def _median_error(geometry, vertices, tract, scale, measured) -> np.ndarray:
    f = np.asarray(tract_formants(geometry, vertices, tract, scale))[:, :3]
    return np.nanmedian(np.abs(f / measured - 1.0), axis=0)


def vowel_quality(label: str) -> str:
    """A vowel label's quality: the label without length marks and stress digits."""
    return label.strip().replace(":", "").rstrip("012")


def leave_one_quality_out(result, *, max_frames: int = MAX_FRAMES):
    """For each vowel quality of ``result`` (an :class:`~cassi_fit.acoustics.Acoustics`)
    with scored frames: the tract fitted to the other qualities' scored frames and the
    model's F1-F3 on this quality's frames with it. Returns ``(held_out (m, 3) Hz, NaN for
    frames not scored or of a quality that could not be held out; fits {quality:
    AcousticFit})``, or ``(None, {})`` with fewer than two qualities (no held-out figure).
    The prior is centred on the norms ``result`` was heard with (``result.norms``)."""
    scored = result.scored
    quality = np.array([vowel_quality(str(s)) for s in result.labels])
    qualities = sorted(set(quality[scored]))
    held = np.full((len(result.times), 3), np.nan)
    if len(qualities) < 2:
        return None, {}
    fits = {}
    geometry, vertices, scale = result.geometry, result.vertices, result.scale
    base = af.default_tract(jnp.asarray(vertices).dtype, result.norms.speaker)
    for q in qualities:
        train = np.nonzero(scored & (quality != q))[0]
        test = np.nonzero(scored & (quality == q))[0]
        fit = fit_tract(geometry, vertices[train], result.measured.frequency[train], scale,
                        base=base, max_frames=max_frames)
        fits[q] = fit
        held[test] = np.asarray(tract_formants(geometry, jnp.asarray(vertices)[test], fit.tract,
                                               scale))[:, :3]
    return held, fits


def tract_record(tract: af.TractParams) -> dict[str, float]:
    """The fitted parameters as plain numbers (for a calibration file or a table)."""
    return {k: float(getattr(tract, k)) for k in ("larynx_drop_mm", "area_scale",
                                                  "pharynx_scale", "lip_scale")}


def tract_from_record(record: dict) -> af.TractParams:
    """:class:`TractParams` from :func:`tract_record`'s numbers."""
    return af.TractParams(*(jnp.asarray(float(record[k])) for k in (
        "larynx_drop_mm", "area_scale", "pharynx_scale", "lip_scale")))



# ------------------------------------------------------------------ the calibration's file
ACOUSTIC_SUFFIX = ".acoustic.json"


def acoustic_calibration_path(folder: str | os.PathLike, subject: str) -> Path:
    """``FOLDER/SUBJECT.acoustic.json``: beside the subject's ``cassi calibrate`` file (a
    sidecar: the face's calibration file and its schema are left as they are)."""
    return Path(folder) / f"{subject}{ACOUSTIC_SUFFIX}"


class CalibratedTract(NamedTuple):
    """:func:`calibrated_tract`'s answer: the subject's fitted ``tract`` (None: the adult
    norms, ``area_function.default_tract``) and ``path``, the acoustic calibration's file
    read, or looked for and not there (``FOLDER/SUBJECT.acoustic.json``; its ``parent`` is
    the folder), None where no calibration was named. :meth:`label` and :meth:`missing`
    word it, once for every caller."""

    tract: af.TractParams | None
    path: Path | None

    def label(self) -> str:
        """Which vocal tract, short (the tract view draws it): ``fitted to the sound
        (FILE)`` or ``the adult norms``."""
        if self.tract is None:
            return "the adult norms"
        return f"fitted to the sound ({self.path.name})"

    def larynx(self) -> str | None:
        """The fitted larynx and where it came from, in words (``cassi acoustics``' norms
        line); None for the adult norms."""
        if self.tract is None:
            return None
        return (f"larynx {float(self.tract.larynx_drop_mm):.0f} mm below the hyoid, "
                f"{self.label()}")

    def missing(self, subject: str) -> str | None:
        """The one line for a calibration named without ``subject``'s file in it (the
        adult norms are used); None otherwise."""
        if self.tract is not None or self.path is None:
            return None
        return f"no acoustic calibration for {subject} in {self.path.parent}: the adult norms"


def calibrated_tract(calibration: str | os.PathLike | None, subject: str) -> CalibratedTract:
    """The subject's fitted vocal tract and where it came from: ``calibration`` is what
    ``--calibration`` names (a folder written by ``cassi calibrate``, or a file in it),
    and ``FOLDER/SUBJECT.acoustic.json`` is read when it is there. The
    :class:`CalibratedTract`'s ``tract`` is None without a calibration (``path`` None too)
    or without that file (``path`` the file looked for)."""
    if not calibration:
        return CalibratedTract(None, None)
    folder = Path(calibration)
    folder = folder if folder.is_dir() else folder.parent
    path = acoustic_calibration_path(folder, subject)
    if not path.is_file():
        return CalibratedTract(None, path)
    return CalibratedTract(read_acoustic_calibration(path)[0], path)


def face_calibration(spec: Any, subject: str) -> tuple[Any, str | None]:
    """``(spec, note)`` for a run whose calibration (a ``run_spec.RunSpec``'s, what
    ``--calibration`` names) is a folder holding ``subject``'s vocal tract
    (``SUBJECT.acoustic.json``, what ``cassi calibrate --acoustic`` writes) but no
    calibration of the face (``SUBJECT.calibration.json``): the spec without it (the face
    keeps its defaults; the folder serves the vocal tract alone) and the one line saying
    so; otherwise the spec as it is and None."""
    from .calibration import calibration_path

    folder = getattr(spec.calibration, "path", None)  # run_spec.CalibrationFiles
    if (folder is None or not Path(folder).is_dir()
            or not acoustic_calibration_path(folder, subject).is_file()
            or calibration_path(folder, subject).is_file()):
        return spec, None
    note = (f"{folder}: no calibration of {subject}'s face, only its vocal tract: the face "
            "with the default calibration")
    return dataclasses.replace(spec, calibration=None), note  # (.replace keeps a None)


def write_acoustic_calibration(path: str | os.PathLike, subject: str, fit: AcousticFit, *,
                               recordings: Sequence[str], frames: int, qualities: Sequence[str],
                               overwrite: bool = False) -> Path:
    """Write a fitted vocal tract (atomically; ``OutputExistsError`` for an existing file
    without ``overwrite``)."""
    from ._io import atomic_write

    record = {"subject": subject, "tract": tract_record(fit.tract), "converged": fit.converged,
              "steps": fit.steps, "recordings": list(recordings), "frames": int(frames),
              "vowel_qualities": list(qualities),
              "median_error_before": [float(x) for x in fit.before],
              "median_error_after": [float(x) for x in fit.after]}
    path = Path(path)
    atomic_write(path, json.dumps(record, indent=2) + "\n", overwrite=overwrite)
    return path


def read_acoustic_calibration(path: str | os.PathLike) -> tuple[af.TractParams, dict]:
    """``(tract, record)`` of a file :func:`write_acoustic_calibration` wrote;
    ``DataFormatError`` naming the file for anything else."""
    from .errors import DataFormatError

    path = Path(path)
    try:
        record = json.loads(path.read_text())
        tract = tract_from_record(record["tract"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DataFormatError(path, None, f"not an acoustic calibration ({exc})") from None
    values = np.array([float(v) for v in record["tract"].values()])
    if not np.all(np.isfinite(values)) or np.any(values[1:] <= 0):
        raise DataFormatError(path, None, "an acoustic calibration with a non-finite or "
                              "non-positive parameter")
    if not record.get("converged", False):
        warnings.warn(f"{path}: this acoustic calibration did not converge", stacklevel=2)
    return tract, record
