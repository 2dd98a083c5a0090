"""The parts of experiments/real_referee.py: what is scored (constants), the geometry of
the scores (point errors, distance to the tongue's surface, rotation about a pivot),
and per recording the jaw's, the tongue's and the lips' predictions of a hidden pellet
against the pellet (the single-sensor couplings among them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable

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
