"""The occlusal frame found from a recording itself: midsagittal plane, occlusal plane, origin.

Used by :mod:`cassi_fit.ema.track` when a recording has no bite plane and no upper-incisor
reference (and, for the midsagittal plane, always). Positions are head-frame millimetres
(after head correction); nothing here reads a file. numpy only.

**Midsagittal plane.** Always fitted (least squares, equal weight per sensor) through the
tracked positions of the midline sensors (the CASSI roles, the upper incisor, nasion, the
sensor map's ``[midline]`` extras). A sensor whose median lies more than
:data:`MIDLINE_OUTLIER_MM` from the plane is dropped and the plane refitted (a lip-corner
or lateral tongue sensor given a midline role). With axes declared by a sensor map, the
declared frame's own midline (its lateral coordinate 0) is compared with the fitted one:
the offset (mm) and tilt (degrees) are reported and corrected.

**Occlusal plane** (the toolkit's x axis within the midsagittal plane), from the first of:
the sensor map's ``[file] occlusal_plane`` (a direction, or ``"declared"``: the declared
anterior axis); else the speaker's jaw, two cues combined by their variances:

* the second jaw sensor (``MNM``, on a lower molar) and the lower-incisor one (``MNI``) at
  the speaker's closed-jaw frames: the line between them runs along the occlusal plane,
  offset by the sensors' depths below the teeth's edges (incisor crown 9.0 mm and molar
  crown 7.5 mm long, Wheeler's Dental Anatomy; each sensor at its tooth's edge or its
  gum: below, *One sensor, one place*), over a molar-incisor distance of 35-45 mm;
* the incisor sensor's opening path in speech (its positions' principal axis): taken as
  pointing down and 13 degrees backward from the occlusal plane's normal, +-12 degrees.
  This is a weak assumption of ours, not a published norm: rotation about the condyles
  alone would tilt the path about 26 degrees backward (Bonwill's triangle at Balkwill's
  angle), the condyles' forward glide brings it toward the vertical; we take the middle.
  Real speakers differ: the XRMB speaker JW11's path is 2 degrees backward, the IPS
  speaker mo1's about 23 (in its file's frame).

Without a jaw sensor the line from the back of the tongue to the lips stands for it (+-15
degrees, said in the report).

**Origin** (the upper incisor's tip). ``[file] origin`` gives it; else two cues combined:

* the jaw: the incisor sensor's position at the speaker's closed-jaw frames (its highest
  2 %), moved to the lower incisal edge (along a crown tilted 14.5 +- 4 degrees forward of
  the occlusal plane's normal, Downs 1948; the sensor's depth below the edge by
  ``[file] jaw_sensor``: ``"edge"`` 1-4 mm, ``"gum"`` at the crown's cervical line, 9.0
  +- 1 mm (Wheeler) plus 0.5-2 mm, ``"unknown"`` either, or a number in mm; 1.5-3 mm
  labial of the crown), then to the upper incisal edge: overjet 2.5 +- 1 mm forward and
  overbite 2 +- 1 mm (Proffit, Contemporary Orthodontics: normal overjet 2-3 mm, overbite
  1-3 mm), less the closest speaking space, 0-3 mm (Silverman 1953), as the highest jaw
  frames of speech are not full occlusion;
* the upper lip: its sensor's median lies ahead of the incisor tip by the lip's thickness
  at the vermilion, 13 +- 3 mm (Holdaway 1983: 13-15 mm), and above it by the incisor's
  exposure below the lip at rest, 1-4 mm (Vig & Brundo 1978), plus the sensor's height on
  the vermilion, 4-12 mm (Farkas 1994: upper vermilion height about 8-9 mm; labs glue the
  sensor anywhere from its middle, about 4 mm, to just above its border; until issue 28
  the draw began at 0 mm, the lip's free edge, where no sensor is glued: the estimate sat
  above the tip. The XRMB speaker JW11's upper-lip pellet sits 18 mm above his incisor
  tip, beyond this range).

**One sensor, one place.** Where the jaw sensors are glued is not a norm drawn afresh for
each cue: the incisor sensor's place (edge or gum, unless ``[file] jaw_sensor`` says)
and a molar sensor's (its edge, 1-4 mm, or its gum, 7.5 +- 0.8 mm crown, Wheeler, plus
0.5-2 mm) are hypotheses, one half each. Under each the plane and the origin are found as
above, and each is weighted by its prior times how well its cues agree: the molar line
with the opening path, the jaw's origin with the upper lip's. The frame is the weighted
mean; the report gives the posterior probability of a gum sensor. (Averaging the
two-peaked depth into one Gaussian, as before issue 28, put the origin between the two
places, where the sensor is not, and let the plane and the origin assume different
depths of one sensor.)

The uncertainty is a Monte Carlo over every norm above and the plane's own uncertainty
(:data:`N_DRAWS` draws, a fixed seed), mixed over the hypotheses: the origin's SD along
and across the plane (mm) and the plane's SD (degrees), reported with the frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import head

#: A midline sensor farther than this (median, mm) from the fitted plane is dropped.
MIDLINE_OUTLIER_MM = 8.0
#: What leaving a sensor out of the midsagittal plane costs (mm of RMS distance).
LEFT_OUT_PENALTY_MM = 1.0
#: Monte Carlo draws of the norms.
N_DRAWS = 2000
#: Share of a session's frames taken as the closed jaw (the incisor sensor's highest).
CLOSED_SHARE = 0.02
#: ... after leaving out the highest this share (tracking spikes).
SPIKE_SHARE = 0.005
JAW_SENSOR_KINDS = ("edge", "gum", "unknown")
_PATH_SD_DEG = 12.0
_PATH_BACK_DEG = 13.0
_COARSE_SD_DEG = 15.0
_MAX_SAMPLES = 1500
_BACK_FIRST = ("T4", "T3", "T2", "T1")
_MOLAR_CROWN_MM = (7.5, 0.8)  # a lower first molar's crown length, mean and SD (Wheeler)
#: The upper-lip sensor's height above the lip's free edge (mm): from the vermilion's middle
#: to just above its border (module docstring).
_UL_ON_VERMILION_MM = (4.0, 12.0)


@dataclass(frozen=True, eq=False)
class Placement:
    """The occlusal frame of one speaker's session and how it was found.

    frame: the change into the toolkit's frame (head-frame mm); source: how, in words;
    origin_sd_mm ``(2,)``: the origin's SD along the occlusal plane and across it (NaN
    when given or measured); plane_sd_deg: the occlusal plane's SD (NaN when given);
    midline: the sensors the midsagittal plane was fitted through; dropped: midline
    sensors left out (median distance mm); midline_offset_mm / midline_tilt_deg: how far
    a declared frame's midline sat from the fitted one (None without declared axes);
    cues: each cue's estimate (for the report).
    """

    frame: head.Frame
    source: str
    origin_sd_mm: np.ndarray
    plane_sd_deg: float
    midline: tuple[str, ...] = ()
    dropped: Mapping[str, float] = field(default_factory=dict)
    midline_offset_mm: float | None = None
    midline_tilt_deg: float | None = None
    cues: Mapping[str, object] = field(default_factory=dict)
    head_config: np.ndarray | None = None  # the session's shared reference configuration
    head_references: tuple[str, ...] = ()  # ... the sensors it holds, in its order

    def to_dict(self) -> dict[str, object]:
        def num(v):
            return None if v is None or not np.isfinite(v) else round(float(v), 3)

        return {"source": self.source,
                "origin_sd_mm": {"along_plane": num(self.origin_sd_mm[0]),
                                 "across_plane": num(self.origin_sd_mm[1])},
                "plane_sd_deg": num(self.plane_sd_deg),
                "midline_sensors": list(self.midline),
                "midline_dropped_mm": {k: round(float(v), 2) for k, v in self.dropped.items()},
                "declared_midline_offset_mm": num(self.midline_offset_mm),
                "declared_midline_tilt_deg": num(self.midline_tilt_deg),
                "cues": {k: v for k, v in self.cues.items()}}


@dataclass(frozen=True)
class Given:
    """What a sensor map says about the frame (head-frame mm / unit directions), or None.

    origin ``(d,)``; occlusal ``(d,)`` forward along the occlusal plane, or the text
    ``"declared"``; forward/up ``(d,)``: declared axes; jaw_sensor: a
    :data:`JAW_SENSOR_KINDS` or a depth (mm).
    """

    origin: np.ndarray | None = None
    occlusal: object = None
    forward: np.ndarray | None = None
    up: np.ndarray | None = None
    jaw_sensor: str | float = "unknown"


class PlacementError(ValueError):
    """The recording's sensors do not give a frame (the message says what to give)."""


# ------------------------------------------------------------------ samples
def _samples(sessions: Sequence[tuple[np.ndarray, Sequence[str]]], name: str | None
             ) -> np.ndarray:
    """Tracked positions of sensor ``name`` over a session's files: ``(m, d)``."""
    if name is None:
        return np.empty((0, sessions[0][0].shape[2]))
    out = []
    for positions, names in sessions:
        if name in names:
            p = positions[:, list(names).index(name)]
            out.append(p[np.isfinite(p).all(-1)])
    return np.concatenate(out) if out else np.empty((0, sessions[0][0].shape[2]))


def _thin(points: np.ndarray, limit: int = _MAX_SAMPLES) -> np.ndarray:
    if points.shape[0] <= limit:
        return points
    return points[np.linspace(0, points.shape[0] - 1, limit).astype(int)]


# ------------------------------------------------------------------ the midsagittal plane
def midsagittal_plane(samples: Mapping[str, np.ndarray], *, max_left_out: int = 3
                      ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], dict[str, float]]:
    """``(unit normal, point, sensors used, dropped sensor -> mean distance)``: the plane
    through the midline sensors' positions, each sensor weighted equally. Robust: every
    way of leaving out up to ``max_left_out`` sensors is tried (from each sensor's mean
    and scatter, so it is cheap); among the planes with every kept sensor within
    :data:`MIDLINE_OUTLIER_MM`, the one kept has the smallest RMS distance of the kept
    sensors' samples plus :data:`LEFT_OUT_PENALTY_MM` per sensor left out. Raises
    :class:`PlacementError` when fewer than three sensors span a plane."""
    from itertools import combinations

    stats = {}
    for k, v in samples.items():
        v = _thin(v[np.isfinite(v).all(-1)])
        if v.shape[0] >= 3:
            mean = v.mean(0)
            stats[k] = (mean, np.cov((v - mean).T, bias=True))
    names = list(stats)
    if len(names) < 2:
        raise PlacementError("too few midline sensors to find the midsagittal plane")
    best = None
    for left in range(0, min(max_left_out, len(names) - 2) + 1):
        for out in combinations(names, left):
            use = [k for k in names if k not in out]
            means = np.array([stats[k][0] for k in use])
            centre = means.mean(0)
            cov = sum(stats[k][1] for k in use) / len(use) + np.cov((means - centre).T,
                                                                   bias=True)
            vals, vecs = np.linalg.eigh(cov)
            if vals[1] <= (head.COLLINEAR_RATIO ** 2) * vals[2]:
                continue
            normal = vecs[:, 0]
            dist = {k: float((stats[k][0] - centre) @ normal) for k in names}
            if max(abs(dist[k]) for k in use) > MIDLINE_OUTLIER_MM:
                continue
            score = float(np.sqrt(max(vals[0], 0.0))) + LEFT_OUT_PENALTY_MM * left
            if best is None or score < best[0]:
                best = (score, normal, centre, tuple(use), {k: dist[k] for k in out})
    if best is not None:
        return best[1:]
    if len(names) < 3:
        raise PlacementError("too few midline sensors to find the midsagittal plane")
    raise PlacementError("the midline sensors do not lie on one plane (no plane through all "
                         f"but {max_left_out} of them within {MIDLINE_OUTLIER_MM:.0f} mm)")


# ------------------------------------------------------------------ in-plane geometry
def _rot2(deg: np.ndarray | float) -> np.ndarray:
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _angle(v: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(v[1], v[0])))


def _closed(jaw2: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """The jaw sensor's closed-jaw position (2D, plane coordinates) with the occlusal plane
    at ``pitch`` degrees from the coarse x axis, and the mask of the frames used."""
    up = np.array([-np.sin(np.deg2rad(pitch)), np.cos(np.deg2rad(pitch))])
    height = jaw2 @ up
    k = max(5, int(round(CLOSED_SHARE * jaw2.shape[0])))
    spikes = int(SPIKE_SHARE * jaw2.shape[0])  # the very highest: a mistrack, not the jaw
    top = np.argsort(height)[-(k + spikes):jaw2.shape[0] - spikes]
    mask = np.zeros(jaw2.shape[0], bool)
    mask[top] = True
    return np.median(jaw2[top], axis=0), mask


def _pitch_from_path(mni2: np.ndarray) -> tuple[float, float] | None:
    """The occlusal plane's angle (deg, in plane coordinates) from the jaw sensor's opening
    path, with its SD; None when the path is too short or not elongated."""
    if mni2.shape[0] < 20:
        return None
    centred = mni2 - mni2.mean(0)
    _, sv, vt = np.linalg.svd(centred, full_matrices=False)
    spread = np.ptp(centred @ vt[0])
    if spread < 4.0 or sv[0] < 1.8 * sv[1]:
        return None
    path = vt[0] if vt[0][1] < 0 else -vt[0]  # pointing down (opening)
    # in the occlusal frame the path points down and _PATH_BACK_DEG backward:
    # (-sin a, -cos a), at angle -90 - a; so the plane's angle is the path's + 90 + a
    return _angle(path) + 90.0 + _PATH_BACK_DEG, _PATH_SD_DEG


def _depth_draws(rng, kind, n, crown: tuple[float, float] = (9.0, 1.0)) -> np.ndarray:
    """A jaw sensor's depth below its tooth's edge along the crown (mm), ``(n,)``: ``"edge"``
    1-4 mm; ``"gum"`` at the crown's cervical line (``crown``: its length's mean and SD,
    Wheeler) plus 0.5-2 mm; or a given depth (mm) +-0.5."""
    if not isinstance(kind, str):
        return np.full(n, float(kind)) + rng.normal(0, 0.5, n)
    if kind == "edge":
        return rng.uniform(1.0, 4.0, n)
    return rng.normal(*crown, n) + rng.uniform(0.5, 2.0, n)


def _kinds(jaw_sensor) -> list[tuple[object, float]]:
    """The incisor sensor's placements to weigh, each with its prior probability: the one
    the sensor map gives, else the edge and the gum, one half each."""
    if isinstance(jaw_sensor, str) and jaw_sensor == "unknown":
        return [("edge", 0.5), ("gum", 0.5)]
    return [(jaw_sensor, 1.0)]


@dataclass(frozen=True)
class _Hypothesis:
    """One placement of the jaw sensors on their teeth and the occlusal plane it gives."""

    kind: object  # the incisor sensor's: "edge", "gum" or a depth (mm)
    molar: str | None  # the molar sensor's: "edge", "gum", or None (no molar sensor)
    prior: float
    pitch: float  # deg, plane coordinates
    pitch_sd: float  # NaN: given, no uncertainty
    log_like: float = 0.0  # how well this placement's plane cues agree (log density)
    molar_pitch: float = np.nan  # the molar-incisor line's plane alone (for the report)


def _pitch_from_molar(mni2, mnm2, kind, molar_kind, rng) -> tuple[float, float]:
    """The occlusal plane's angle from the MNM -> MNI line at the closed jaw, and its SD,
    with the incisor sensor glued as ``kind`` and the molar's as ``molar_kind``."""
    p_i, _ = _closed(mni2, 0.0)
    p_m, _ = _closed(mnm2, 0.0)
    observed = _angle(p_i - p_m)
    n = N_DRAWS
    d_i = _depth_draws(rng, kind, n)
    d_m = _depth_draws(rng, molar_kind, n, _MOLAR_CROWN_MM)
    length = rng.uniform(35.0, 45.0, n)
    # MNM -> MNI in the occlusal frame: forward `length`, down by (d_i - d_m)
    expected = np.degrees(np.arctan2(-(d_i - d_m), length))
    return observed - float(expected.mean()), float(expected.std())


def _combine(cues: Sequence[tuple[float, float]]) -> tuple[float, float]:
    w = np.array([1.0 / sd ** 2 for _, sd in cues])
    mean = float(sum(wi * a for wi, (a, _) in zip(w, cues, strict=True)) / w.sum())
    return mean, float(1.0 / np.sqrt(w.sum()))


def _log_agreement(diff, cov) -> float:
    """``log N(diff; 0, cov)``: how well two cues' estimates of one quantity agree."""
    diff, cov = np.atleast_1d(diff), np.atleast_2d(cov)
    return float(-0.5 * diff @ np.linalg.solve(cov, diff)
                 - 0.5 * np.log(np.linalg.det(2.0 * np.pi * cov)))


def _jaw_hypotheses(jaw_sensor, mni2, mnm2, rng) -> tuple[list[_Hypothesis], str] | None:
    """The occlusal plane under each placement of the jaw sensors (the incisor's by
    :func:`_kinds`, a molar sensor's at its edge or gum, one half each): the molar-incisor
    line and the opening path combined, each placement scored by how well the two agree;
    and the words. None without a jaw cue."""
    path = _pitch_from_path(mni2)
    molar = mni2.shape[0] >= 20 and mnm2.shape[0] >= 20
    if path is None and not molar:
        return None
    out = []
    for kind, prior in _kinds(jaw_sensor):
        for molar_kind, molar_prior in ((("edge", 0.5), ("gum", 0.5)) if molar
                                        else ((None, 1.0),)):
            found = [] if molar_kind is None else [
                _pitch_from_molar(mni2, mnm2, kind, molar_kind, rng)]
            found += [path] if path is not None else []
            log_like = 0.0 if len(found) < 2 else _log_agreement(
                found[0][0] - found[1][0], found[0][1] ** 2 + found[1][1] ** 2)
            pitch, sd = _combine(found)
            out.append(_Hypothesis(kind, molar_kind, prior * molar_prior, pitch, sd, log_like,
                                   found[0][0] if molar else np.nan))
    words = " and ".join(w for w, c in (("the molar-incisor jaw line", molar),
                                        ("the jaw's opening path", path is not None)) if c)
    return out, words


def _origin_draws(mni2, ul2, pitch_draws, kind, rng) -> tuple[np.ndarray, dict, float]:
    """Monte Carlo origins (plane coordinates) ``(n, 2)`` combining the jaw and upper-lip
    cues with the incisor sensor glued as ``kind``, each cue's own draws (for the report)
    and how well the two cues agree (log density; 0 with one cue)."""
    n = pitch_draws.shape[0]
    rot = _rot2(pitch_draws)  # occlusal frame -> plane coordinates
    cues = {}
    if mni2.shape[0] >= 20:
        closed = np.stack([_closed(mni2, float(p))[0] for p in np.quantile(
            pitch_draws, np.linspace(0.02, 0.98, 9))])
        closed = closed[rng.integers(0, closed.shape[0], n)]
        tilt = np.deg2rad(rng.normal(14.5, 4.0, n))
        depth = _depth_draws(rng, kind, n)
        labial = rng.uniform(1.5, 3.0, n)
        # in the occlusal frame: from the sensor to the lower edge, then to the upper edge
        to_edge = (depth[:, None] * np.stack([np.sin(tilt), np.cos(tilt)], 1)
                   - labial[:, None] * np.stack([np.cos(tilt), -np.sin(tilt)], 1))
        overjet = rng.normal(2.5, 1.0, n)
        overbite = rng.normal(2.0, 1.0, n)
        speaking = rng.uniform(0.0, 3.0, n)
        to_upper = np.stack([overjet, -overbite + speaking], 1)
        cues["jaw"] = closed + np.einsum("nij,nj->ni", rot, to_edge + to_upper)
    if ul2.shape[0] >= 20:
        ul = np.median(ul2, axis=0)
        ahead = rng.normal(13.0, 3.0, n)
        above = rng.uniform(1.0, 4.0, n) + rng.uniform(*_UL_ON_VERMILION_MM, n)
        cues["upper_lip"] = ul - np.einsum("nij,nj->ni", rot, np.stack([ahead, above], 1))
    if not cues:
        raise PlacementError("no jaw sensor and no upper-lip sensor to estimate the origin")
    covs = {k: np.cov(d.T) + 1e-9 * np.eye(2) for k, d in cues.items()}
    weights = {k: np.linalg.inv(c) for k, c in covs.items()}
    total = np.linalg.inv(sum(weights.values()))
    combined = sum(np.einsum("ij,nj->ni", total @ weights[k], d) for k, d in cues.items())
    log_like = 0.0 if len(cues) < 2 else _log_agreement(
        cues["jaw"].mean(0) - cues["upper_lip"].mean(0), covs["jaw"] + covs["upper_lip"])
    return combined, cues, log_like


# ------------------------------------------------------------------ the estimate
def _median_of(samples: np.ndarray) -> np.ndarray | None:
    return None if samples.shape[0] == 0 else np.median(samples, axis=0)


def _coarse_axes(meds: Mapping[str, np.ndarray], roles: Mapping[str, str], given: Given,
                 to_plane) -> tuple[np.ndarray, np.ndarray, str]:
    """Unit forward and up vectors (data dims) within the plane before the pitch: the
    declared axes, else the line from the back of the tongue to the lips with up from
    the lower lip to the upper."""
    def med(role):
        name = roles.get(role)
        return None if name is None else meds.get(name)

    lips = [p for p in (med("UL"), med("LL")) if p is not None]
    back = next((p for r in _BACK_FIRST if (p := med(r)) is not None), None)
    if given.forward is not None:
        fwd = to_plane(given.forward)
        up = to_plane(given.up)
        return fwd, up, "declared axes"
    if not lips or back is None:
        raise PlacementError("cannot tell the front from the back: the lips and a tongue "
                             "sensor are needed, or the axes in the sensor map's [file] table")
    fwd = to_plane(np.mean(lips, axis=0) - back)
    ul, ll = med("UL"), med("LL")
    vertical = (ul - ll) if ul is not None and ll is not None else None
    return fwd, vertical, "the tongue-lips line"


def _plane_basis(fwd: np.ndarray, up_hint: np.ndarray | None, normal: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    e1 = fwd / np.linalg.norm(fwd)
    if normal is None:
        e2 = np.array([-e1[1], e1[0]])
    else:
        e2 = np.cross(normal, e1)
    if up_hint is not None and np.dot(e2, up_hint) < 0:
        e2 = -e2
    return e1, e2


def _weights(hyps: Sequence[_Hypothesis], log_like=0.0) -> np.ndarray:
    """Each placement's posterior probability: its prior times how well its cues agree."""
    logs = np.log([h.prior for h in hyps]) + np.array([h.log_like for h in hyps]) + log_like
    w = np.exp(logs - logs.max())
    return w / w.sum()


def _mixed_pitch(hyps: Sequence[_Hypothesis], w: np.ndarray) -> tuple[float, float]:
    """The occlusal plane's angle and SD over the weighted placements (SD NaN: given)."""
    pitch = float(sum(wi * h.pitch for wi, h in zip(w, hyps, strict=True)))
    if not all(np.isfinite(h.pitch_sd) for h in hyps):
        return pitch, np.nan
    var = sum(wi * (h.pitch_sd ** 2 + (h.pitch - pitch) ** 2)
              for wi, h in zip(w, hyps, strict=True))
    return pitch, float(np.sqrt(var))


def _pitch(given, e1, e2, mni2, mnm2, rng, declared_words):
    """``(placement hypotheses, words, cues)``: the occlusal plane under each placement of
    the jaw sensors (:func:`_jaw_hypotheses`), or the one plane given or assumed."""
    cues: dict[str, object] = {}
    if isinstance(given.occlusal, str):
        pitch, sd, words = (0.0, np.nan,
                            "the declared anterior axis (occlusal_plane = \"declared\")")
    elif given.occlusal is not None:
        v = np.asarray(given.occlusal, float)
        pitch, sd, words = (_angle(np.array([v @ e1, v @ e2])), np.nan,
                            "given by the sensor map ([file] occlusal_plane)")
    elif (found := _jaw_hypotheses(given.jaw_sensor, mni2, mnm2, rng)) is not None:
        hyps, words = found
        if np.isfinite(hyps[0].molar_pitch):
            cues["plane_from_molar_deg"] = round(sum(h.prior * h.molar_pitch for h in hyps), 2)
        if (path := _pitch_from_path(mni2)) is not None:
            cues["plane_from_jaw_path_deg"] = round(path[0], 2)
        return hyps, f"estimated from {words}", cues
    elif declared_words == "declared axes":
        pitch, sd, words = 0.0, np.nan, "the declared anterior axis (no jaw sensor to estimate it)"
    else:
        pitch, sd, words = 0.0, _COARSE_SD_DEG, ("the line from the back of the tongue to the "
                                                 "lips (no jaw sensor to estimate it)")
    return [_Hypothesis(k, None, p, pitch, sd) for k, p in _kinds(given.jaw_sensor)], words, cues


def _estimated_origin(mni2, ul2, hyps, rng, cues):
    """``(pitch, its SD, origin (2,), its SD (2,) along/across the plane, words)``: the jaw
    and upper-lip cues under each placement hypothesis, the placements weighted by their
    prior and how well their cues agree (on the plane and on the origin). Each cue's own
    estimate (the placements weighted by their prior alone) is added to ``cues``, in
    occlusal axes from the estimate, with the posterior probability of a gum sensor."""
    n, runs = N_DRAWS, []
    for h in hyps:
        draws = h.pitch + (rng.normal(0, h.pitch_sd, n) if np.isfinite(h.pitch_sd)
                           else np.zeros(n))
        runs.append(_origin_draws(mni2, ul2, draws, h.kind, rng))
    w = _weights(hyps, np.array([r[2] for r in runs]))
    pitch, pitch_sd = _mixed_pitch(hyps, w)
    back, pick = _rot2(-pitch), np.arange(n)
    o2 = sum(wi * r[0].mean(0) for wi, r in zip(w, runs, strict=True))
    combined = np.stack([r[0] for r in runs])[rng.choice(len(hyps), n, p=w), pick]
    origin_sd = np.einsum("ij,nj->ni", back, combined - combined.mean(0)).std(0)
    idx = rng.choice(len(hyps), n, p=np.array([h.prior for h in hyps]))
    own = {k: np.stack([r[1][k] for r in runs])[idx, pick] for k in runs[0][1]}
    for k, v in own.items():
        cues[f"origin_from_{k}_mm"] = [round(float(x), 2) for x in back @ (v.mean(0) - o2)]
    if len(own) == 2:
        apart = np.einsum("ij,nj->ni", back, own["jaw"] - own["upper_lip"])
        cues["origin_cue_sd_mm"] = [round(float(x), 2) for x in apart.std(0)]
    if len({str(h.kind) for h in hyps}) > 1:
        cues["jaw_sensor_gum_probability"] = round(float(sum(
            wi for wi, h in zip(w, hyps, strict=True) if h.kind == "gum")), 3)
    words = " and ".join({"jaw": "the jaw sensor at the closed jaw with dental norms",
                          "upper_lip": "the upper lip"}[k] for k in own)
    return pitch, pitch_sd, o2, origin_sd, f"estimated from {words}"


def estimate_placement(sessions: Sequence[tuple[np.ndarray, Sequence[str]]],
                       roles: Mapping[str, str], midline: Sequence[str],
                       given: Given = Given(), *, upper_incisor: str | None = None,
                       seed: int = 0) -> Placement:
    """The occlusal frame of one speaker's session (module docstring).

    ``sessions``: ``(positions (n, k, d) head-frame mm, names)`` per file (the same
    head frame for all); ``roles``: CASSI role -> sensor name; ``midline``: the sensors
    on the midline; ``upper_incisor``: a reference on the upper incisor (the origin).
    Raises :class:`PlacementError` saying what is missing."""
    dims = sessions[0][0].shape[2]
    rng = np.random.default_rng(seed)
    samples = {s: _samples(sessions, s) for s in dict.fromkeys(midline)}
    meds = {s: m for s, v in samples.items() if (m := _median_of(v)) is not None}
    offset = tilt = None
    dropped: dict[str, float] = {}
    used = tuple(meds)
    if dims == 3:
        normal, centre, used, dropped = midsagittal_plane(samples)

        def to_plane(v):
            return None if v is None else v - np.dot(v, normal) * normal
        if given.forward is not None:
            lateral = np.cross(given.up, given.forward)
            lateral = lateral / np.linalg.norm(lateral)
            offset = float(np.dot(centre, lateral))
            tilt = float(np.degrees(np.arccos(min(1.0, abs(np.dot(normal, lateral))))))
    else:
        normal, centre = None, np.zeros(2)

        def to_plane(v):
            return v
    fwd, up_hint, declared_words = _coarse_axes(meds, roles, given, to_plane)
    e1, e2 = _plane_basis(fwd, up_hint, normal)

    def plane2(points):
        return np.stack([(points - centre) @ e1, (points - centre) @ e2], -1)

    mni2 = plane2(_samples(sessions, roles.get("MNI")))
    mnm2 = plane2(_samples(sessions, roles.get("MNM")))
    ul2 = plane2(_samples(sessions, roles.get("UL")))
    hyps, pitch_words, cues = _pitch(given, e1, e2, mni2, mnm2, rng, declared_words)
    ui = _samples(sessions, upper_incisor)
    origin_sd = np.full(2, np.nan)
    if given.origin is not None:
        o2 = plane2(np.asarray(given.origin, float)[None])[0]
        origin_words = "given by the sensor map ([file] origin)"
    elif ui.shape[0]:
        o2 = plane2(np.median(ui, axis=0)[None])[0]
        origin_words = f"the upper-incisor sensor {upper_incisor}"
    else:
        pitch, pitch_sd, o2, origin_sd, origin_words = _estimated_origin(mni2, ul2, hyps, rng,
                                                                         cues)
    if given.origin is not None or ui.shape[0]:
        pitch, pitch_sd = _mixed_pitch(hyps, _weights(hyps))
    x2 = np.array([np.cos(np.deg2rad(pitch)), np.sin(np.deg2rad(pitch))])
    y2 = np.array([-x2[1], x2[0]])
    x, y = x2[0] * e1 + x2[1] * e2, y2[0] * e1 + y2[1] * e2
    origin = centre + o2[0] * e1 + o2[1] * e2
    rows = [x, y] if dims == 2 else [x, y, np.cross(y, x)]
    source = f"occlusal plane: {pitch_words}; origin: {origin_words}"
    if np.isfinite(pitch_sd):
        source += f" (+-{pitch_sd:.1f} deg)"
    if np.isfinite(origin_sd).all():
        source += f" (+-{origin_sd[0]:.1f} mm along, +-{origin_sd[1]:.1f} mm across the plane)"
    if dims == 3:
        source += f"; midsagittal plane through {', '.join(used)}"
        if dropped:
            source += " (off the midline, left out: " + ", ".join(
                f"{k} {v:+.1f} mm" for k, v in dropped.items()) + ")"
        if offset is not None and (abs(offset) > 2.0 or tilt > 3.0):
            source += (f"; the declared frame's midline sat {offset:+.1f} mm off its zero "
                       f"(tilted {tilt:.1f} deg): corrected")
    return Placement(frame=head.Frame(np.stack(rows), origin, source), source=source,
                     origin_sd_mm=np.asarray(origin_sd, float), plane_sd_deg=float(pitch_sd),
                     midline=tuple(used), dropped=dropped, midline_offset_mm=offset,
                     midline_tilt_deg=tilt, cues=cues)
