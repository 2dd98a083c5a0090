"""Real recordings as the referee: every model predicts a sensor it never saw.

    python experiments/real_referee.py DATASET [--out DIR] [--docs DIR] [--force]
        [--label NAME] [--subjects S ...] [--tasks T ...]
        [--synthetic DIR|default|none] [--synthetic-subjects N] [--synthetic-tasks T ...]

DATASET is any folder of XRMB recordings (either layout, ``cassi_fit.dataset.Dataset``),
e.g. the real JW11 task 5 in /work/shared/data/xrmb_jw11/. Beside it the same is run on the
synthetic corpus (``cassi_fit.synth.ensure_default_corpus()``, its speech tasks
``SYNTHETIC_TASKS``; ``--synthetic-subjects`` and ``--synthetic-tasks`` choose a subset,
``--synthetic DIR`` another corpus, ``--synthetic none`` none). Per recording, three
held-out tests, each scored on the frames where every pellet it uses and the hidden one
are tracked and not flagged by the mistrack detector (``PelletTrack.mistracks``), the
reference frame excluded:

- **Jaw** (:func:`jaw_part`). With both jaw sensors present, each is hidden in turn (MNM
  predicted from MNI alone, MNI from MNM alone). Methods: the library's single-sensor jaw
  methods (:func:`single_sensor_methods`, ``jaw_from_track(..., jaw_sensors=SEEN)``,
  ``JawFit.hidden_predicted``); "coupled-rotation" gets a coupling learned on other
  speakers only (:class:`Couplings`). Baselines: ``static`` (the hidden sensor stays at
  its reference-frame position) and ``translate`` (it moves as the seen sensor does).
  References that saw both sensors: ``two-pellet fixed pivot`` (``jaw_from_track(method=
  "fixed-pivot")`` on both pellets, its motion applied to the hidden sensor's reference
  position) and ``two-pellet pivot, seen angle`` (that pivot, each frame's angle from the
  seen sensor alone: a single-sensor method with a perfect pivot prior). Score: the
  distance (mm) between the predicted and the measured hidden sensor.
- **Tongue** (:func:`tongue_part`). With all four tongue pellets present, T2 and T3 are
  hidden in turn (the recording loaded with that pellet never tracked) and the toolkit's
  own pipeline (``pipeline.run_recording``) runs in the improved mode (thick tongue) and in
  the cassi mode (CASSI's flat tongue), every ``TONGUE_STRIDE``-th line; whatever the
  pipeline does with a never-tracked tongue pellet (today ``frames.tongue_fill``: its
  displacement interpolated in arc length between its neighbours') is what is scored.
  Scores: ``surface``, the distance from the measured hidden pellet to the model tongue's
  upper midsagittal contour (the polyline of its upper-midline vertices,
  ``deform.tongue_midline``: the section of the tongue's surface at z = 0); ``site``, the
  distance to where the model puts the hidden pellet (``Animation.pellets_model``);
  ``along``, the distance along the contour from that site to the foot of the
  perpendicular from the measured pellet (the tangential part of ``site``). Baseline:
  linear interpolation between the neighbouring pellets (``surface``: the distance to the
  chord between them; ``site``: the point at the model's rest arc-length fraction along it).
- **Lips** (:func:`lips_part`). The lower lip (LL, held out) predicted from the jaw
  alone: the jaw's motion from the reference frame (the pipeline's jaw method with both
  jaw pellets, ``run_spec.IMPROVED.jaw_method_for(("MNI", "MNM"))``: the closed form) applied to LL's reference position with
  the model's lower-lip jaw weight (``rigid.fractional``; CASSI's weight 1.11 and Parke's
  1.0). Baselines: ``static`` and ``moves with MNI``. The jaw pellets are not held out
  here; UL has no model predictor (the model moves it by its own pellet only): not scored.

Statistics: the median and 95th percentile of the per-frame errors, per recording and
pooled over a dataset's recordings (frames pooled), each with a 95 % percentile-bootstrap
interval of ``BOOTSTRAP`` resamples: within a recording a moving-block bootstrap (blocks of
``BLOCK_S`` seconds of consecutive scored frames: neighbouring frames share movement and
noise); pooled, subjects resampled with replacement (with all their recordings), then
blocks within each recording. Paired comparisons: a method's statistic minus a baseline's
(or a reference's) on the same resampled frames, with its interval; ``better``/``worse``
only where the interval excludes 0, else ``tie``. Every resample is seeded from names
(dataset, subject, task, part), so a re-run of one recording reproduces its rows exactly.

Writes ``real_referee.csv`` (every row), ``real_referee_couplings.csv`` (the couplings
learned) and ``real_referee.md`` (the side-by-side tables, rendered from the CSVs) into
--out (default experiments/output) and, with --docs, into that folder too; the Markdown's
first line names the command. Outputs are checked before any work and never replaced
without --force. Fits and animations run on tracks padded with untracked frames to a
multiple of ``PAD_FRAMES`` (:func:`padded`), so that they compile once per length class.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
import zlib
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from cassi_fit import rigid

BOOTSTRAP = 1000
BLOCK_S = 0.34  # bootstrap block length, s (50 frames at 145.6 Hz)
PAD_FRAMES = 512  # tracks padded (untracked) to a multiple of this many frames
TONGUE_STRIDE = 3  # every 3rd line animated for the tongue (48.5 Hz)
TONGUE_METRICS = ("surface", "site", "along")
LEVEL = 95.0
STATISTICS = {"median": 50.0, "p95": 95.0}
JAW = ("MNI", "MNM")
TONGUE = ("T1", "T2", "T3", "T4")
HIDDEN_TONGUE = ("T2", "T3")
#: The tongue models scored: label -> the pipeline's mode (``options.MODES``).
TONGUE_MODELS = {"thick tongue (improved)": "improved", "flat tongue (cassi)": "cassi"}
#: The lower lip's jaw weight of each weight set (``options.JAW_WEIGHTS``), as labels.
LIP_MODELS = {"jaw weight (cassi)": "cassi", "jaw weight (parke)": "parke"}
SYNTHETIC_TASKS = ("tp011", "tp020", "tp040")  # the speech tasks (vcv, words, sentence)
SYNTHETIC_LABEL = "synthetic"
#: The issue's hand measurements on JW11 (issue 20): MNM from MNI, median and p95 (mm).
ISSUE_JW11 = {  # label here: (the issue's words, median, p95, what differs)
    "translate": ("translating MNM with MNI", 1.3, 6.2, ""),
    "two-pellet pivot, seen angle": ("the two-pellet fixed pivot", 1.0, 2.5, ""),
    "fixed pivot, free": ("a fixed pivot fitted freely to MNI alone", 7.3, 22.6, ""),
    "fixed pivot at the population condyle": (
        "a pivot at a population condyle", 3.6, 7.5,
        "the issue does not say which condyle position it used; here the library's "
        "POPULATION_CONDYLE mean"),
}
OUTPUT_NAMES = ("real_referee.csv", "real_referee_couplings.csv", "real_referee.md")
COLUMNS = ("dataset", "subject", "task", "part", "metric", "predictor", "role", "versus",
           "frames", "recordings", "subjects", "median_mm", "median_lo_mm", "median_hi_mm",
           "median_verdict", "p95_mm", "p95_lo_mm", "p95_hi_mm", "p95_verdict")


# ---------------------------------------------------------------------------- scoring
def point_errors(predicted: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Distances (n,) mm between predicted and observed positions (n, 2) mm; NaN where
    either is NaN (an undefined prediction or an unobserved sensor)."""
    return np.linalg.norm(np.asarray(predicted, float) - np.asarray(observed, float), axis=-1)


def polyline_distance(points: np.ndarray, polylines: np.ndarray):
    """The nearest point of each polyline to each point.

    points (n, 2) mm; polylines (n, k, 2) mm, one per point (k >= 2 vertices in order).
    Returns ``(distance (n,) mm, arc (n,) mm)``: the distance to the polyline and the arc
    length from its first vertex to the foot of the perpendicular.
    """
    p = np.asarray(points, float)[:, None, :]
    a, b = polylines[:, :-1, :], polylines[:, 1:, :]
    ab = b - a
    length2 = np.sum(ab * ab, axis=-1)
    safe = np.where(length2 > 0.0, length2, 1.0)  # a zero-length segment: its first end
    t = np.where(length2 > 0.0, np.clip(np.sum((p - a) * ab, axis=-1) / safe, 0.0, 1.0), 0.0)
    foot = a + t[..., None] * ab
    dist = np.linalg.norm(foot - p, axis=-1)  # (n, k - 1)
    nearest = np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=1)
    rows = np.arange(len(p))
    arc = arc_lengths(polylines)[rows, nearest] + t[rows, nearest] * np.sqrt(length2[rows, nearest])
    return dist[rows, nearest], arc


def arc_lengths(polylines: np.ndarray) -> np.ndarray:
    """Cumulative arc length (n, k) mm at each vertex of polylines (n, k, 2) mm."""
    seg = np.linalg.norm(np.diff(polylines, axis=1), axis=-1)
    return np.concatenate([np.zeros((len(polylines), 1)), np.cumsum(seg, axis=1)], axis=1)


def rotate_about(pivot: np.ndarray, theta: np.ndarray, point: np.ndarray) -> np.ndarray:
    """``R(theta) (point - pivot) + pivot`` (paper Eqs 4-5): the point (2,) mm turned by
    each angle theta (n,) rad about the pivot (2,) or (n, 2) mm; (n, 2) mm."""
    c, s = np.cos(theta), np.sin(theta)
    u = np.asarray(point, float) - pivot
    u = np.broadcast_to(u, (len(theta), 2))
    return np.stack([c * u[:, 0] + s * u[:, 1], -s * u[:, 0] + c * u[:, 1]], -1) + pivot


def angle_about(pivot: np.ndarray, reference: np.ndarray, current: np.ndarray) -> np.ndarray:
    """The angle (n,) rad that turns ``reference`` (2,) mm onto the direction of each
    ``current`` (n, 2) mm about ``pivot`` (2,) mm, in the sense of :func:`rotate_about`."""
    u = np.asarray(reference, float) - pivot
    v = np.asarray(current, float) - pivot
    return np.arctan2(v[:, 0] * u[1] - v[:, 1] * u[0], v @ u)


def apply_motion(theta: np.ndarray, translation: np.ndarray, point: np.ndarray,
                 weight: float = 1.0) -> np.ndarray:
    """The point (2,) mm moved by the fraction ``weight`` of each motion ``p' = R(theta) p
    + t`` (theta (n,) rad, translation (n, 2) mm; ``rigid.fractional``, Parke's region
    weights): (n, 2) mm. Compiled once per n (pass padded arrays)."""
    return np.asarray(_moved(jnp.asarray(theta, float), jnp.asarray(translation, float),
                             jnp.asarray(point, float), jnp.asarray(weight, float)))


@jax.jit
def _moved(theta, translation, point, weight):
    def one(th, t):
        return rigid.apply(*rigid.fractional((th, t), weight), point)

    return jax.vmap(one)(theta, translation)


# -------------------------------------------------------------------------- recordings
def clean_values(track) -> np.ndarray:
    """(n, 8) bool: the pellet's x and y tracked and not flagged as mistracked (the
    track's one detection, ``PelletTrack.mistracks``)."""
    return track.valid.all(axis=2) & ~np.asarray(track.mistracks.flags, bool)


def _col(name: str) -> int:
    from cassi_fit.pellets import pellet_index

    return pellet_index(name)


def _ever(clean: np.ndarray, names: Iterable[str]) -> bool:
    return all(clean[:, _col(n)].sum() >= 2 for n in names)


def padded(track, multiple: int = PAD_FRAMES):
    """The track with untracked frames appended up to a multiple of ``multiple`` frames.

    Fits and animations compile once per frame count; padding gives recordings of
    similar length one count. The appended frames are never used (untracked) nor scored.
    """
    n = track.n_frames
    extra = -n % multiple

    def pad(values, fill):
        values = np.asarray(values)
        return np.concatenate([values, np.full((extra, *values.shape[1:]), fill, values.dtype)])

    times = track.times[-1] + track.frame_step_s * np.arange(1, extra + 1)
    return dataclasses.replace(
        track, times=np.concatenate([track.times, times]),
        positions=pad(track.positions, np.nan), valid=pad(track.valid, False),
        extra_positions=pad(track.extra_positions, np.nan),
        extra_valid=pad(track.extra_valid, False))


class PartResult:
    """One held-out test on one recording: per-frame errors (n,) mm of every predictor
    (NaN where not scored), their roles, the frames scored by all of them, and the time
    step (s) between those frames' neighbours (for the bootstrap's block length)."""

    def __init__(self, part: str, metric: str, errors: dict[str, np.ndarray],
                 roles: dict[str, str], step_s: float):
        self.part, self.metric, self.roles, self.step_s = part, metric, roles, step_s
        stacked = np.stack([np.asarray(e, float) for e in errors.values()])
        self.frames = np.flatnonzero(np.isfinite(stacked).all(axis=0))
        self.errors = {k: np.asarray(v, float)[self.frames] for k, v in errors.items()}

    @property
    def block(self) -> int:
        """Frames per bootstrap block: ``BLOCK_S`` seconds of this part's frames."""
        return max(1, int(round(BLOCK_S / self.step_s)))


def two_pellet_fit(track):
    """The fixed pivot fitted to both jaw pellets (``jaw_from_track`` on the padded track,
    ``n_pad`` frames): ``(theta (n_pad,), translation (n_pad, 2), pivot (2,), ok (n,) bool
    (usable frames of the track), reference_frame)``."""
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.status import Status

    n = track.n_frames
    fit = jaw_from_track(padded(track), method="fixed-pivot")
    ok = np.asarray(fit.status)[:n] <= Status.PIVOT_UNDEFINED
    return fit.theta, fit.translation, fit.pivot[fit.reference_frame], ok, fit.reference_frame


def jaw_part(track, seen: str, fit=None, single_sensor: Callable | None = None) -> list[PartResult]:
    """The hidden-sensor test: ``seen`` jaw sensor in, the other predicted (mm).
    ``fit``: :func:`two_pellet_fit` of the track (computed when None)."""
    hidden = JAW[1 - JAW.index(seen)]
    s, h = _col(seen), _col(hidden)
    clean = clean_values(track)
    theta, translation, pivot, ok, f0 = two_pellet_fit(track) if fit is None else fit
    usable = clean[:, s] & clean[:, h] & ok
    usable[f0] = False
    pos = track.positions
    predicted = {
        "static": np.broadcast_to(pos[f0, h], pos[:, h].shape),
        "translate": pos[f0, h] + pos[:, s] - pos[f0, s],
        "two-pellet fixed pivot": apply_motion(theta, translation, pos[f0, h])[:len(ok)],
        "two-pellet pivot, seen angle": rotate_about(
            pivot, angle_about(pivot, pos[f0, s], pos[:, s]), pos[f0, h]),
    }
    roles = {"static": "baseline", "translate": "baseline",
             "two-pellet fixed pivot": "reference (saw both)",
             "two-pellet pivot, seen angle": "reference (saw both)"}
    if single_sensor is not None:
        for name, pred in single_sensor(track, seen, f0).items():
            predicted[name], roles[name] = pred, "method"
    errors = {k: np.where(usable, point_errors(v, pos[:, h]), np.nan) for k, v in predicted.items()}
    order = [k for k in roles if roles[k] == "method"] + [k for k in roles if roles[k] != "method"]
    return [PartResult(f"jaw: {hidden} from {seen}", "position", {k: errors[k] for k in order},
                       {k: roles[k] for k in order}, track.frame_step_s)]


def _hide(recording, name: str):
    """The recording, padded (:func:`padded`), with pellet ``name`` never tracked."""
    track = padded(recording.track)
    valid = track.valid.copy()
    valid[:, _col(name)] = False
    return dataclasses.replace(recording, track=dataclasses.replace(track, valid=valid))


def tongue_contour(model) -> np.ndarray:
    """Vertex indices (k,) of the tongue's upper midline, front to back: its midsagittal
    surface contour (ring vertex 0 of every station, ``deform.tongue_midline``)."""
    from cassi_fit.deform import tongue_midline

    return np.unique(tongue_midline(model)[1])


def tongue_part(recording, hidden: str, model=None,
                models: dict[str, str] | None = None) -> list[PartResult]:
    """The hidden tongue pellet test (``hidden`` in T2, T3): one result per metric.
    ``models``: label -> mode of the tongue models to run (default ``TONGUE_MODELS``)."""
    from cassi_fit.pipeline import run_recording

    models = TONGUE_MODELS if models is None else models
    i = TONGUE.index(hidden)
    before, after = TONGUE[i - 1], TONGUE[i + 1]
    track = recording.track
    n = track.n_frames
    used = clean_values(track)[:, [_col(k) for k in TONGUE]].all(axis=1)
    pos = track.positions
    errors = {m: {} for m in TONGUE_METRICS}
    fraction, scored = None, np.zeros(n, bool)
    for label, mode in models.items():
        _, _, state, anim, _ = run_recording(_hide(recording, hidden), mode, model=model,
                                          stride=TONGUE_STRIDE)
        rows = np.asarray(anim.frame_index)
        keep = rows < n
        rows = rows[keep]
        contour_idx = tongue_contour(state.model)
        contour = np.asarray(anim.vertices)[keep][:, contour_idx, :2] / state.scale
        site = np.asarray(anim.pellets_model)[keep][:, _col(hidden)] / state.scale
        observed = pos[rows, _col(hidden)]
        dist, arc = polyline_distance(observed, contour)
        k_site = int(np.searchsorted(contour_idx, state.model.landmarks[hidden]))
        along = np.abs(arc - arc_lengths(contour)[:, k_site])
        ok = used[rows] & (rows != state.first_frame)
        scored[rows[ok]] = True
        for metric, value in (("surface", dist), ("site", point_errors(site, observed)),
                              ("along", along)):
            full = np.full(n, np.nan)
            full[rows] = np.where(ok, value, np.nan)
            errors[metric][label] = full
        if fraction is None:
            s = np.asarray(state.model.fields["tongue_s"])
            site_s = [s[state.model.landmarks[k]] for k in (before, hidden, after)]
            fraction = (site_s[1] - site_s[0]) / (site_s[2] - site_s[0])
    a, b = pos[:, _col(before)], pos[:, _col(after)]
    observed = pos[:, _col(hidden)]
    chord_dist, chord_arc = polyline_distance(observed, np.stack([a, b], axis=1))
    chord_len = np.linalg.norm(b - a, axis=-1)
    baseline = {"surface": chord_dist,
                "site": point_errors(a + fraction * (b - a), observed),
                "along": np.abs(chord_arc - fraction * chord_len)}
    part = f"tongue: {hidden} from {', '.join(k for k in TONGUE if k != hidden)}"
    roles = {k: "method" for k in models} | {"linear interpolation": "baseline"}
    out = []
    for metric in TONGUE_METRICS:
        errs = dict(errors[metric])
        errs["linear interpolation"] = np.where(scored, baseline[metric], np.nan)
        out.append(PartResult(part, metric, errs, roles, TONGUE_STRIDE * track.frame_step_s))
    return out


def lips_part(track, model=None) -> list[PartResult]:
    """The lower lip predicted from the jaw alone (LL held out, both jaw pellets used)."""
    from cassi_fit.face_model import load_model
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.pellets import first_valid_line
    from cassi_fit.run_spec import IMPROVED
    from cassi_fit.status import Status

    model = load_model() if model is None else model
    n = track.n_frames
    clean = clean_values(track)
    ll, mni = _col("LL"), _col("MNI")
    f0 = first_valid_line(track, pellets=("MNI", "MNM", "LL")).index
    fit = jaw_from_track(padded(track), method=IMPROVED.jaw_method_for(JAW),
                         reference_frame=f0)
    usable = clean[:, [ll, mni, _col("MNM")]].all(axis=1)
    usable &= np.asarray(fit.status)[:n] <= Status.PIVOT_UNDEFINED
    usable[f0] = False
    pos = track.positions
    predicted = {}
    for label, weights in LIP_MODELS.items():
        w = float(np.asarray(model.jaw_weights[weights])[model.landmarks["LL"]])
        predicted[f"{label}, w = {w:.2f}"] = apply_motion(fit.theta, fit.translation,
                                                          pos[f0, ll], w)[:n]
    roles = {k: "method" for k in predicted}
    predicted["static"] = np.broadcast_to(pos[f0, ll], pos[:, ll].shape)
    predicted["moves with MNI"] = pos[f0, ll] + pos[:, mni] - pos[f0, mni]
    roles |= {"static": "baseline", "moves with MNI": "baseline"}
    errors = {k: np.where(usable, point_errors(v, pos[:, ll]), np.nan) for k, v in predicted.items()}
    return [PartResult("lips: LL from the jaw", "position", errors, roles, track.frame_step_s)]


def single_sensor_methods(coupling: Callable[[str], object]) -> dict[str, object]:
    """The single-sensor jaw methods scored (``cassi_fit.jaw_fit``), by label.

    ``coupling(sensor)``: the :class:`~cassi_fit.jaw_fit.JawCoupling` to give
    "coupled-rotation" for that seen sensor (learned on other speakers:
    :class:`Couplings`). The pivot methods' priors: none (the pivot fitted to the one
    sensor), the library's one-sensor default (``POPULATION_CONDYLE``, a mean and an SD),
    and that mean held fixed (an SD of 0.01 mm: the issue's "pivot at a population
    condyle").
    """
    from cassi_fit.jaw_fit import (
        PIVOT_FROM_DATA,
        POPULATION_CONDYLE,
        CoupledRotation,
        FixedPivot,
        PivotPrior,
        SmoothPivot,
    )

    at_condyle = PivotPrior(POPULATION_CONDYLE.mean_mm, (0.01, 0.01),
                            "held at the population condyle's mean")
    return {
        "coupled rotation": lambda sensor: CoupledRotation(coupling=coupling(sensor)),
        "fixed pivot, population prior": lambda sensor: FixedPivot(),
        "smooth pivot, population prior": lambda sensor: SmoothPivot(),
        "fixed pivot at the population condyle": lambda sensor: FixedPivot(pivot_prior=at_condyle),
        "fixed pivot, free": lambda sensor: FixedPivot(pivot_prior=PIVOT_FROM_DATA),
    }


def single_sensor_predictor(coupling: Callable[[str], object]) -> Callable:
    """``predict(track, seen, f0) -> {label: (n, 2) mm}``: every single-sensor method of
    :func:`single_sensor_methods` given only the ``seen`` jaw sensor (reference frame
    ``f0``), its prediction of the hidden one (``JawFit.hidden_predicted``; NaN in frames
    the fit did not use)."""
    from cassi_fit.jaw_fit import jaw_from_track
    from cassi_fit.status import Status

    methods = single_sensor_methods(coupling)

    def predict(track, seen, f0):
        n, out = track.n_frames, {}
        for label, make in methods.items():
            fit = jaw_from_track(padded(track), method=make(seen), jaw_sensors=seen,
                                 reference_frame=f0)
            used = np.asarray(fit.status)[:n] <= Status.PIVOT_UNDEFINED
            out[label] = np.where(used[:, None], fit.hidden_predicted[:n], np.nan)
        return out

    return predict


class Couplings:
    """The coupling of "coupled-rotation" for each speaker, learned on other speakers.

    ``tracks``: ``(dataset, subject) -> [PelletTrack]`` of every recording in the run.
    For a speaker, the coupling is learned (``jaw_fit.learn_jaw_coupling``) from the
    other subjects of its dataset, or, where its dataset has no other subject, from every
    other dataset's recordings: never from the recording scored nor from its speaker.
    """

    def __init__(self, tracks: dict[tuple[str, str], list]):
        self.tracks = {k: [padded(t) for t in v] for k, v in tracks.items()}
        self.learned: dict[tuple[str, str, str], object] = {}

    def training(self, dataset: str, subject: str) -> list[tuple[str, str]]:
        """The ``(dataset, subject)`` keys a speaker's coupling is learned from."""
        same = [k for k in self.tracks if k[0] == dataset and k[1] != subject]
        return same or [k for k in self.tracks if k[0] != dataset]

    def get(self, dataset: str, subject: str, sensor: str):
        """The :class:`~cassi_fit.jaw_fit.JawCoupling` for ``sensor`` of that speaker."""
        from cassi_fit.jaw_fit import learn_jaw_coupling

        key = (dataset, subject, sensor)
        if key not in self.learned:
            keys = self.training(dataset, subject)
            tracks = [t for k in keys for t in self.tracks[k]]
            names = sorted({d for d, _ in keys})
            source = (f"{', '.join(names)}: {len(tracks)} recordings of {len(keys)} other "
                      "speakers")
            self.learned[key] = learn_jaw_coupling(tracks, sensor, source=source)
        return self.learned[key]

    def rows(self) -> list[dict]:
        """One row per coupling learned (``COUPLING_COLUMNS``)."""
        return [coupling_row(d, s, c) for (d, s, _), c in self.learned.items()]


COUPLING_COLUMNS = ("dataset", "subject", "sensor", "rad_per_mm_x", "rad_per_mm_y",
                    "theta_sd_rad", "frames", "source")
#: Decimals of the couplings' CSV: enough that a coupling read back predicts the same
#: positions to well below the tables' micrometre.
COUPLING_DIGITS = {"rad_per_mm_x": 12, "rad_per_mm_y": 12, "theta_sd_rad": 12}


def coupling_row(dataset: str, subject: str, coupling) -> dict:
    """A coupling as a table row (its coefficient SD, not learned here, is left out)."""
    return {"dataset": dataset, "subject": subject, "sensor": coupling.sensor,
            "rad_per_mm_x": coupling.rad_per_mm[0], "rad_per_mm_y": coupling.rad_per_mm[1],
            "theta_sd_rad": coupling.theta_sd_rad, "frames": coupling.frames,
            "source": coupling.source}


def coupling_from_row(row: dict):
    """The :class:`~cassi_fit.jaw_fit.JawCoupling` of a :func:`coupling_row`."""
    from cassi_fit.jaw_fit import JawCoupling

    return JawCoupling(row["sensor"], (row["rad_per_mm_x"], row["rad_per_mm_y"]),
                       row["theta_sd_rad"], (0.0, 0.0), int(row["frames"]), row["source"])


def recording_parts(recording, model=None, single_sensor: Callable | None = None) -> list[PartResult]:
    """Every held-out test the recording allows (its pellets decide)."""
    track = recording.track
    clean = clean_values(track)
    parts: list[PartResult] = []
    if _ever(clean, JAW):
        fit = two_pellet_fit(track)
        for seen in JAW:
            parts += jaw_part(track, seen, fit, single_sensor)
    if _ever(clean, TONGUE + JAW):
        for hidden in HIDDEN_TONGUE:
            parts += tongue_part(recording, hidden, model)
    if _ever(clean, ("LL", *JAW)):
        parts += lips_part(track, model)
    return parts


# --------------------------------------------------------------------------- bootstrap
def _rng(*names: object) -> np.random.Generator:
    """A generator seeded from names (stable across runs and processes)."""
    return np.random.default_rng(zlib.crc32("/".join(map(str, names)).encode()))


def block_starts(n: int, rng: np.random.Generator, block: int,
                 n_boot: int = BOOTSTRAP) -> np.ndarray:
    """Start indices (n_boot, ceil(n / block)) of a moving-block bootstrap of n frames."""
    block = max(1, min(block, n))
    return rng.integers(0, n - block + 1, size=(n_boot, -(-n // block)))


def resample_index(starts: np.ndarray, n: int, block: int) -> np.ndarray:
    """Frame indices (..., n) of resamples given by their block starts (..., n_blocks)."""
    block = max(1, min(block, n))
    index = starts[..., None] + np.arange(block)
    return index.reshape(*starts.shape[:-1], -1)[..., :n]


def _interval(stats: np.ndarray) -> tuple[float, float]:
    lo, hi = np.percentile(stats, [(100 - LEVEL) / 2, 100 - (100 - LEVEL) / 2])
    return float(lo), float(hi)


def _verdict(lo: float, hi: float) -> str:
    return "better" if hi < 0 else "worse" if lo > 0 else "tie"


def _stat_rows(base: dict, values: dict[str, np.ndarray], boot: dict[str, np.ndarray],
               roles: dict[str, str], frames: int) -> list[dict]:
    """Rows of every predictor and of every method-minus-baseline pair.

    values: predictor -> {statistic: value}; boot: predictor -> (n_stats, B) resampled."""
    rows = []
    for name, role in roles.items():
        row = dict(base, predictor=name, role=role, versus="", frames=frames)
        for k, key in enumerate(STATISTICS):
            lo, hi = _interval(boot[name][k])
            row |= {f"{key}_mm": values[name][k], f"{key}_lo_mm": lo, f"{key}_hi_mm": hi,
                    f"{key}_verdict": ""}
        rows.append(row)
    for name, role in roles.items():  # methods against baselines and references;
        if role == "baseline":  # references against baselines
            continue
        for other, other_role in roles.items():
            if other_role == role or (role != "method" and other_role != "baseline"):
                continue
            row = dict(base, predictor=name, role=f"{role} - {other_role}", versus=other,
                       frames=frames)
            for k, key in enumerate(STATISTICS):
                lo, hi = _interval(boot[name][k] - boot[other][k])
                row |= {f"{key}_mm": values[name][k] - values[other][k], f"{key}_lo_mm": lo,
                        f"{key}_hi_mm": hi, f"{key}_verdict": _verdict(lo, hi)}
            rows.append(row)
    return rows


def _percentiles(values: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.percentile(values, list(STATISTICS.values()), axis=axis)


def recording_rows(dataset: str, subject: str, task: str, result: PartResult) -> list[dict]:
    """Per-recording rows of one part: every predictor's median and 95th percentile with
    their block-bootstrap intervals, and the paired differences."""
    n = len(result.frames)
    base = {"dataset": dataset, "subject": subject, "task": task, "part": result.part,
            "metric": result.metric, "recordings": 1, "subjects": 1}
    if n == 0:
        return []
    starts = block_starts(n, _rng(dataset, subject, task, result.part), result.block)
    index = resample_index(starts, n, result.block)
    values = {k: _percentiles(v) for k, v in result.errors.items()}
    boot = {k: _percentiles(v[index]) for k, v in result.errors.items()}
    return _stat_rows(base, values, boot, result.roles, n)


def pooled_rows(dataset: str, results: Sequence[tuple[str, str, PartResult]]) -> list[dict]:
    """Pooled rows of one part over recordings ``(subject, task, result)``: frames pooled;
    the bootstrap resamples subjects (with all their recordings), then blocks of frames
    within each recording (the same blocks as the per-recording rows)."""
    results = [r for r in results if len(r[2].frames)]
    if not results:
        return []
    first = results[0][2]
    subjects = sorted({s for s, _, _ in results})
    starts = [block_starts(len(r.frames), _rng(dataset, s, t, r.part), r.block)
              for s, t, r in results]
    by_subject = {s: [k for k, (sub, _, _) in enumerate(results) if sub == s] for s in subjects}
    rng = _rng(dataset, "pooled", first.part)
    names = list(first.roles)
    values = {k: _percentiles(np.concatenate([r.errors[k] for _, _, r in results])) for k in names}
    boot = {k: np.empty((len(STATISTICS), BOOTSTRAP)) for k in names}
    for b in range(BOOTSTRAP):
        chosen = rng.choice(len(subjects), size=len(subjects), replace=True)
        picks = [k for c in chosen for k in by_subject[subjects[c]]]
        index = [resample_index(starts[k][b], len(results[k][2].frames), results[k][2].block)
                 for k in picks]
        for name in names:
            sample = np.concatenate([results[k][2].errors[name][i] for k, i in zip(picks, index,
                                                                                  strict=True)])
            boot[name][:, b] = _percentiles(sample)
    base = {"dataset": dataset, "subject": "pooled", "task": "pooled", "part": first.part,
            "metric": first.metric, "recordings": len(results), "subjects": len(subjects)}
    frames = sum(len(r.frames) for _, _, r in results)
    return _stat_rows(base, values, boot, first.roles, frames)


# ------------------------------------------------------------------------------- runs
def dataset_recordings(root, subjects=None, tasks=None):
    """Yield ``(subject, task, recording)`` of every recording of the folder ``root``
    (restricted to ``subjects`` / ``tasks`` when given)."""
    from cassi_fit.dataset import Dataset

    data = Dataset(root)
    for subject in data.subjects():
        if subjects and subject not in {s.upper() for s in subjects}:
            continue
        for task in data.tasks(subject):
            if tasks and task not in {t.lower() for t in tasks}:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # default head measures
                recording = data.load(subject, task)
            yield subject, task, recording


def run(datasets: Sequence[tuple[str, object, object, object]], model=None,
        progress: Callable[[str], None] | None = None) -> tuple[list[dict], list[dict]]:
    """Every recording's rows and each part's pooled rows of every dataset, and the
    couplings learned. ``datasets``: ``(label, folder, subjects or None, tasks or None)``."""
    from cassi_fit.face_model import load_model

    model = load_model() if model is None else model
    loaded = {label: list(dataset_recordings(root, subjects, tasks))
              for label, root, subjects, tasks in datasets}
    tracks: dict[tuple[str, str], list] = {}
    for label, recordings in loaded.items():
        for subject, _, recording in recordings:
            tracks.setdefault((label, subject), []).append(recording.track)
    couplings = Couplings(tracks)
    rows = []
    for label, recordings in loaded.items():
        by_part = {}
        for subject, task, recording in recordings:
            if progress:
                progress(f"{label} {subject} {task}")
            single = single_sensor_predictor(
                lambda sensor, label=label, subject=subject: couplings.get(label, subject, sensor))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                parts = recording_parts(recording, model, single)
            for result in parts:
                rows += recording_rows(label, subject, task, result)
                by_part.setdefault((result.part, result.metric), []).append(
                    (subject, task, result))
        for results in by_part.values():
            rows += pooled_rows(label, results)
    return rows, couplings.rows()


# ---------------------------------------------------------------------------- tables
INTEGER_COLUMNS = ("frames", "recordings", "subjects")
TEXT_COLUMNS = ("dataset", "subject", "task", "part", "metric", "predictor", "role", "versus",
                "median_verdict", "p95_verdict", "sensor", "source")


def parse_rows(text: str) -> list[dict]:
    """Rows of ``real_referee.csv`` (or ``real_referee_couplings.csv``) text, numbers as
    numbers (the inverse of ``tables.csv_text`` up to its 6 decimals)."""
    import csv
    import io

    rows = []
    for raw in csv.DictReader(io.StringIO(text)):
        rows.append({k: v if k in TEXT_COLUMNS else int(v) if k in INTEGER_COLUMNS
                     else float(v) for k, v in raw.items()})
    return rows


def _cell(row: dict | None, key: str, verdict: bool = False) -> str:
    if row is None or not np.isfinite(row[f"{key}_mm"]):
        return "-"
    text = f"{row[f'{key}_mm']:.2f} [{row[f'{key}_lo_mm']:.2f}, {row[f'{key}_hi_mm']:.2f}]"
    return f"{text} {row[f'{key}_verdict']}" if verdict else text


def _pooled(rows, dataset, part, metric):
    return [r for r in rows if r["dataset"] == dataset and r["subject"] == "pooled"
            and r["part"] == part and r["metric"] == metric]


def _datasets(rows) -> list[str]:
    return list(dict.fromkeys(r["dataset"] for r in rows))


def _dataset_title(rows, dataset) -> str:
    pooled = [r for r in rows if r["dataset"] == dataset and r["subject"] == "pooled"]
    n_rec = max((r["recordings"] for r in pooled), default=0)
    n_sub = max((r["subjects"] for r in pooled), default=0)
    return f"{dataset} ({n_rec} rec., {n_sub} subj.)"


def part_tables(rows, part: str, metric: str) -> str:
    """Two Markdown tables of one part and metric, the datasets side by side: every
    predictor's pooled median and 95th percentile [95 % interval]; the paired differences
    (method minus baseline or reference, on the same frames) with their verdicts."""
    from cassi_fit.tables import markdown_text

    datasets = _datasets(rows)
    by_dataset = {d: _pooled(rows, d, part, metric) for d in datasets}
    names = list(dict.fromkeys(r["predictor"] for d in datasets for r in by_dataset[d]
                               if not r["versus"]))
    errors, paired, headers = [], [], {}
    for name in names:
        role = next(r["role"] for d in datasets for r in by_dataset[d]
                    if r["predictor"] == name and not r["versus"])
        row = {"predictor": name, "role": role}
        for d in datasets:
            found = next((r for r in by_dataset[d] if r["predictor"] == name and not r["versus"]),
                         None)
            row[f"{d} median"], row[f"{d} p95"] = _cell(found, "median"), _cell(found, "p95")
            row[f"{d} frames"] = "-" if found is None else found["frames"]
        errors.append(row)
    pairs = list(dict.fromkeys((r["predictor"], r["versus"]) for d in datasets
                               for r in by_dataset[d] if r["versus"]))
    for name, other in pairs:
        row = {"comparison": f"{name} - {other}"}
        for d in datasets:
            found = next((r for r in by_dataset[d] if (r["predictor"], r["versus"])
                          == (name, other)), None)
            row[f"{d} median"] = _cell(found, "median", verdict=True)
            row[f"{d} p95"] = _cell(found, "p95", verdict=True)
        paired.append(row)
    for d in datasets:
        title = _dataset_title(rows, d)
        headers |= {f"{d} median": f"{title}: median [95 % CI]",
                    f"{d} p95": f"{title}: 95th pct [95 % CI]", f"{d} frames": f"{d}: frames"}
    text = markdown_text(errors, headers=headers)
    if paired:
        text += "\nPaired, on the same frames (mm; negative: the first predicts better):\n\n"
        text += markdown_text(paired, headers=headers)
    return text


def headline(rows) -> str:
    """One Markdown table: per part (and metric) and dataset, the method and the baseline
    with the lowest pooled median, and their paired difference with its verdict (a
    lowest point estimate names no winner: the verdict says whether the interval does)."""
    from cassi_fit.tables import markdown_text

    table = []
    for part, metric in dict.fromkeys((r["part"], r["metric"]) for r in rows):
        if metric == "along":
            continue
        for d in _datasets(rows):
            pooled = _pooled(rows, d, part, metric)
            plain = [r for r in pooled if not r["versus"]]
            best = {role: min((r for r in plain if r["role"] == role), default=None,
                              key=lambda r: r["median_mm"]) for role in ("method", "baseline")}
            if best["method"] is None or best["baseline"] is None:
                continue
            paired = next(r for r in pooled if (r["predictor"], r["versus"])
                          == (best["method"]["predictor"], best["baseline"]["predictor"]))
            table.append({
                "part": f"{part} ({metric})", "dataset": d,
                "lowest method: median [95 % CI]":
                    f"{best['method']['predictor']}: {_cell(best['method'], 'median')}",
                "lowest baseline: median [95 % CI]":
                    f"{best['baseline']['predictor']}: {_cell(best['baseline'], 'median')}",
                "method - baseline: median": _cell(paired, "median", verdict=True),
                "method - baseline: 95th pct": _cell(paired, "p95", verdict=True)})
    return markdown_text(table) if table else "No part has both a method and a baseline.\n"


def issue_check(rows, dataset: str) -> str:
    """The issue's hand measurements on JW11 beside this run's (MNM from MNI)."""
    from cassi_fit.tables import markdown_text

    pooled = _pooled(rows, dataset, "jaw: MNM from MNI", "position")
    table = []
    for name, (words, median, p95, differs) in ISSUE_JW11.items():
        found = next((r for r in pooled if r["predictor"] == name and not r["versus"]), None)
        table.append({"issue 20": words, "by hand": f"{median:.1f} ({p95:.1f})",
                      "predictor here": name,
                      "this run": "not run" if found is None
                      else f"{found['median_mm']:.2f} ({found['p95_mm']:.2f})",
                      "what differs": differs or "nothing"})
    return markdown_text(table)


PART_TEXT = {
    ("jaw", "position"): "Distance (mm) between the predicted and the measured hidden jaw "
    "sensor. Methods see one jaw sensor (`jaw_from_track(..., jaw_sensors=SEEN)`: the "
    "coupled rotation with a coupling learned on other speakers, below; the fixed and "
    "smooth pivots with the library's one-sensor prior, a population condyle with an SD of "
    "15 mm; a fixed pivot held at that condyle; a fixed pivot fitted freely); the "
    "baselines need nothing but that sensor; the references saw both sensors (the goal a "
    "single-sensor method would like to reach).",
    ("tongue", "surface"): "Distance (mm) from the measured hidden pellet to the tongue's "
    "upper midsagittal contour (methods: the model's tongue posed by the pipeline without "
    "the pellet; baseline: the chord between the neighbouring pellets).",
    ("tongue", "site"): "Distance (mm) from the measured hidden pellet to where the model "
    "puts it (its pellet site; baseline: the point on the chord at the model's rest "
    "arc-length fraction).",
    ("tongue", "along"): "The tangential part of the site error: distance (mm) along the "
    "contour (chord) from the predicted site to the foot of the perpendicular from the "
    "measured pellet.",
    ("lips", "position"): "Distance (mm) between the predicted and the measured lower lip. "
    "Held out: LL. Not held out: both jaw pellets (the jaw motion, by the pipeline's jaw "
    "method). The lip's own motion (#65/#66) has no predictor in the model: this error is "
    "what the model needs the LL pellet for.",
}


def _dataset_note(rows, dataset) -> str:
    recordings = sorted({(r["subject"], r["task"]) for r in rows
                         if r["dataset"] == dataset and r["subject"] != "pooled"})
    subjects = sorted({s for s, _ in recordings})
    if dataset == SYNTHETIC_LABEL:
        tasks = sorted({t for _, t in recordings})
        return (f"`{dataset}`: the toolkit's synthetic corpus, {len(recordings)} recordings of "
                f"{len(subjects)} subjects (tasks {', '.join(tasks)}). Its generator shares "
                "assumptions with the models scored here: it is no referee, only a comparison "
                "of how the two behave.")
    if len(recordings) == 1:
        (subject, task), = recordings
        return (f"`{dataset}`: real, one recording of one speaker ({subject}, task {task}). "
                "Its numbers say what this speaker did in this task, not what speakers do.")
    return (f"`{dataset}`: real, {len(recordings)} recordings of {len(subjects)} speakers "
            f"({', '.join(subjects)}).")


def couplings_markdown(couplings: Sequence[dict]) -> str:
    """The couplings used, per dataset and sensor: one speaker's as they are, several
    speakers' as the median [min, max] of their coefficients (deg of jaw rotation per mm
    of the sensor's displacement, x forward and y up)."""
    from cassi_fit.tables import markdown_text

    def spread(values):
        values = np.rad2deg(values)
        if len(values) == 1:
            return f"{values[0]:.3f}"
        return f"{np.median(values):.3f} [{values.min():.3f}, {values.max():.3f}]"

    table = []
    for d, sensor in dict.fromkeys((c["dataset"], c["sensor"]) for c in couplings):
        group = [c for c in couplings if (c["dataset"], c["sensor"]) == (d, sensor)]
        table.append({
            "dataset": d, "sensor": sensor, "speakers": len(group),
            "deg per mm, x": spread(np.array([c["rad_per_mm_x"] for c in group])),
            "deg per mm, y": spread(np.array([c["rad_per_mm_y"] for c in group])),
            "scatter (deg)": spread(np.array([c["theta_sd_rad"] for c in group])),
            "learned from": group[0]["source"] if len(group) == 1
            else "for each speaker, the others of its dataset"})
    return markdown_text(table) if table else "No coupling was learned.\n"


def markdown(rows, command: str, couplings: Sequence[dict] = ()) -> str:
    """The whole Markdown report; its first line names the command that wrote it.
    ``couplings``: the rows of ``real_referee_couplings.csv``."""
    datasets = _datasets(rows)
    real = [d for d in datasets if d != SYNTHETIC_LABEL]
    parts = [
        f"<!-- written by `{command}`; do not edit: `make experiments` rewrites it -->",
        "# Real recordings as the referee: held-out sensors",
        "",
        "Written by `experiments/real_referee.py` (its docstring says exactly what is held "
        "out and how each error is measured). Each model predicts a pellet it never saw, "
        "and the measured pellet is the referee. Datasets side by side: "
        + ", ".join(f"`{d}`" for d in datasets) + ".",
        "",
        *(f"- {_dataset_note(rows, d)}" for d in datasets),
        "",
        f"Statistics: the median and 95th percentile of the per-frame errors, frames pooled "
        f"over a dataset's recordings, with 95 % percentile-bootstrap intervals ({BOOTSTRAP} "
        f"resamples: subjects resampled with all their recordings, then blocks of "
        f"{BLOCK_S} s of consecutive frames within each recording; with one subject "
        "the interval reflects only the frames of its recordings). Paired rows: a predictor's "
        "statistic minus another's on the same resampled frames; `better`/`worse` only where "
        "the interval excludes 0, else `tie`. Per-recording rows are in `real_referee.csv`.",
        "",
    ]
    parts += ["## Headline", "", "Per held-out test, the method and the baseline with the "
              "lowest pooled median (mm), and the method minus the baseline on the same "
              "frames; the sections below give every predictor.", "", headline(rows), ""]
    seen = list(dict.fromkeys((r["part"], r["metric"]) for r in rows))
    for part, metric in seen:
        kind = part.split(":")[0]
        parts += [f"## {part[0].upper() + part[1:]} ({metric})", "", PART_TEXT[(kind, metric)],
                  "", part_tables(rows, part, metric), ""]
    parts += ["## Couplings of the coupled rotation", "",
              "Learned (`jaw_fit.learn_jaw_coupling`: the two-sensor frame fit's angle "
              "regressed on the seen sensor's displacement) for each speaker from other "
              "speakers only, never from the recording scored: from the other subjects of "
              "its dataset, or, where its dataset has none, from the other datasets. Every "
              "coupling is in `real_referee_couplings.csv`.", "", couplings_markdown(couplings),
              ""]
    for d in real:
        parts += [f"## Check against the issue's hand measurements ({d})", "",
                  "Issue 20 measured these by hand on JW11 task 5 (MNM from MNI, median "
                  "(95th percentile), mm); the rows above reproduce them where the library "
                  "has the method.", "", issue_check(rows, d), ""]
    return "\n".join(parts)


# ------------------------------------------------------------------------------- main
def _command(argv) -> str:
    return " ".join(["python experiments/real_referee.py", *argv])


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="a folder of XRMB recordings (e.g. the real JW11)")
    parser.add_argument("--label", help="the dataset's name in the tables (default: the "
                        "folder's name)")
    parser.add_argument("--subjects", nargs="+", help="only these subjects of DATASET")
    parser.add_argument("--tasks", nargs="+", help="only these tasks of DATASET")
    parser.add_argument("--synthetic", default="default", help="the synthetic corpus beside "
                        "it: a folder, 'default' (ensure_default_corpus) or 'none'")
    parser.add_argument("--synthetic-subjects", type=int, help="only the first N subjects")
    parser.add_argument("--synthetic-tasks", nargs="+", default=list(SYNTHETIC_TASKS),
                        help=f"synthetic tasks (default: {' '.join(SYNTHETIC_TASKS)})")
    parser.add_argument("--out", default="experiments/output", help="folder for the tables")
    parser.add_argument("--docs", help="also write the tables into this folder")
    parser.add_argument("--force", action="store_true", help="replace existing outputs")
    args = parser.parse_args(argv)

    from cassi_fit._io import atomic_write, check_outputs
    from cassi_fit.errors import CassiError
    from cassi_fit.tables import csv_text

    root = Path(args.dataset)
    if not root.is_dir():
        print(f"real_referee: {root}: not a folder", file=sys.stderr)
        return 1
    folders = [Path(args.out)] + ([Path(args.docs)] if args.docs else [])
    try:  # refuse before any work, as the toolkit's writers do
        outputs = check_outputs([f / n for f in folders for n in OUTPUT_NAMES],
                                overwrite=args.force)
    except CassiError as exc:
        print(f"real_referee: {exc} (pass --force to replace it)", file=sys.stderr)
        return 1

    import jax

    jax.config.update("jax_enable_x64", True)  # errors of a few hundredths of a mm
    from cassi_fit import synth

    def progress(text):
        print(f"real_referee: {text}", file=sys.stderr, flush=True)

    label = args.label or root.name
    datasets = [(label, root, args.subjects, args.tasks)]
    if args.synthetic != "none":
        corpus = synth.ensure_default_corpus() if args.synthetic == "default" \
            else Path(args.synthetic)
        names = None if args.synthetic_subjects is None \
            else synth.subject_names(args.synthetic_subjects)
        datasets.append((SYNTHETIC_LABEL, corpus, names, args.synthetic_tasks))
    rows, couplings = run(datasets, progress=progress)
    table = csv_text(rows, COLUMNS)
    coupling_table = csv_text(couplings, COUPLING_COLUMNS, digits=COUPLING_DIGITS)
    # the Markdown shows exactly what the CSVs hold
    rows, couplings = parse_rows(table), parse_rows(coupling_table)
    text = markdown(rows, _command(argv), couplings)
    content = {OUTPUT_NAMES[0]: table, OUTPUT_NAMES[1]: coupling_table, OUTPUT_NAMES[2]: text}
    for path in outputs:
        atomic_write(path, content[path.name], overwrite=args.force)
    print(issue_check(rows, label))
    return 0


if __name__ == "__main__":
    sys.exit(main())
