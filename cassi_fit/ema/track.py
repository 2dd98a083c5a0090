"""From an articulograph file's sensors to the toolkit's pellet track.

:func:`ema_to_track` takes a :class:`~cassi_fit.ema._raw.RawEma` (any reader's output), a
sensor map and optionally a bite-plane recording, and returns the
:class:`~cassi_fit.txy.PelletTrack` the pipeline reads (positions ``(n, 8, 2)`` mm in the
toolkit's frame for ``UL LL T1 T2 T3 T4 MNI MNM``, NaN where a role has no sensor or is
untracked; every other sensor in ``extra_*``) with a
:class:`~cassi_fit.ema.report.SensorReport` saying how. The steps:

1. units: the reader's millimetres, times a sensor map's ``[file] scale_mm``;
2. roles (:mod:`cassi_fit.ema.sensor_map`);
3. head correction on the reference sensors (:mod:`cassi_fit.ema.head`);
4. the occlusal frame, from the first of these that applies:

   a. a bite-plane recording (3D or 2D; its references fitted onto this recording's head
      frame, so the head may move between the two recordings);
   b. axes declared by the sensor map's ``[file]`` table (data already in a head frame),
      origin at the upper-incisor sensor if there is one;
   c. the format's documented frame (MOCHA-TIMIT: x toward the back, so x is mirrored;
      origin at the ``ui`` coil);
   d. 2D data: the file's axes, each sign chosen by the anatomy (the upper lip lies in
      front of the back of the tongue and above the lower lip), origin at the
      upper-incisor sensor if there is one, else the file's; the occlusal plane's angle is
      then unknown and the file's x axis stands for it (said in the report);
   e. 3D data with an upper-incisor sensor: the midsagittal plane fitted through the
      midline sensors, x from the back of the tongue toward the upper lip within it (an
      approximation of the occlusal plane, said in the report), origin at the incisor;
   f. otherwise a :class:`DataFormatError`: 3D device coordinates cannot be placed
      without a bite plane, an incisor sensor or declared axes;

5. 3D data are projected onto the midsagittal plane (the toolkit's z = 0), and each
   sensor's median distance from it is reported;
6. checks: the sensors must span a head (15 to 250 mm: else the units are wrong), and the
   anatomy must hold in the toolkit frame (:func:`cassi_fit.pellets.plausibility_problem`:
   upper lip above lower lip, tongue behind the lips...), else a :class:`DataFormatError`
   naming the file and what to check.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import DataFormatError
from ..pellets import PELLET_NAMES, plausibility_problem
from ..txy import PelletTrack
from . import anatomy, head, placement
from ._raw import RawEma, untrack_impossible
from .report import SensorReport
from .sensor_map import PROPOSED, Assignment, SensorMap, resolve, sensor_map

#: The span of the CASSI sensors' median positions (mm) of any head: outside it the
#: units are wrong (a normalised array, centimetres, hundredths of a millimetre).
SPAN_RANGE_MM = (15.0, 250.0)
#: At most this many files of a session (spread over it) give its frame.
SESSION_FILES = 40
_BACK_FIRST = ("T4", "T3", "T2", "T1")


@dataclass(frozen=True, eq=False)
class _Corrected:
    positions: np.ndarray  # (n, k, d) in the head frame
    fits: head.RigidFits | None
    config: np.ndarray | None
    references: tuple[str, ...]
    level: str
    description: str


def _median(positions: np.ndarray) -> np.ndarray:
    """Per sensor median over frames, NaN for a sensor never tracked: ``(k, d)``."""
    out = np.full(positions.shape[1:], np.nan)
    for j in range(positions.shape[1]):
        ok = np.isfinite(positions[:, j]).all(-1)
        if ok.any():
            out[j] = np.median(positions[ok, j], axis=0)
    return out


def _correct(where, positions: np.ndarray, assign: Assignment,
             config: np.ndarray | None = None) -> _Corrected:
    refs = assign.reference_names
    dims = positions.shape[2]
    level = head.reference_level(dims, len(refs))
    if level == "none":
        return _Corrected(positions, None, None, (), level, "none (no reference sensors: "
                          "head movement stays in the data)")
    index = [assign.names.index(r) for r in refs]
    ref_pos = positions[:, index]
    if config is None or config.shape != ref_pos.shape[1:]:
        config = head.reference_configuration(ref_pos, level)
    if config is None:
        raise DataFormatError(where, None, f"no frame has every reference sensor "
                              f"({', '.join(refs)}) tracked: the head frame cannot be set "
                              "(name fewer references in a sensor map)")
    fits = head.fit_references(ref_pos, config, level)
    words = {
        "full": f"rigid, {len(refs)} references ({', '.join(refs)})",
        "two": (f"partial, 2 references ({', '.join(refs)}): translation and tilt removed, "
                "the rotation about the line through them cannot be"),
        "translation": f"translation only, 1 reference ({refs[0]}): rotations cannot be removed",
    }
    return _Corrected(head.apply(fits, positions), fits, config, refs, level, words[level])


def _bite_points(bite: RawEma, smap: SensorMap, corrected: _Corrected, scale: float):
    """Median bite-plane sensor positions in this recording's head frame, and a note."""
    where = bite.path
    assign = resolve(bite.names, smap, where, bite_plane=True)
    for kind in ("front", "back"):
        if kind not in assign.bite:
            raise DataFormatError(where, None, f"bite-plane recording has no {kind} sensor "
                                  f"(its sensors: {', '.join(assign.names)}; defaults OS, MS)")
    positions = bite.positions * scale
    note = None
    if corrected.fits is not None:
        missing = [r for r in corrected.references if r not in assign.names]
        if missing:
            raise DataFormatError(where, None, f"bite-plane recording lacks the reference "
                                  f"sensor(s) {', '.join(missing)} of the recording")
        index = [assign.names.index(r) for r in corrected.references]
        fits = head.fit_references(positions[:, index], corrected.config, corrected.level)
        positions = head.apply(fits, positions)
    else:
        note = ("bite plane used without head references: the head is assumed not to have "
                "moved between the bite-plane recording and this one")
    med = _median(positions)
    points = {k: med[assign.names.index(s)] for k, s in assign.bite.items()}
    for kind, p in points.items():
        if not np.isfinite(p).all():
            raise DataFormatError(where, None, f"bite-plane {kind} sensor "
                                  f"{assign.bite[kind]!r} is never tracked")
    return points, note


def _up_hint(med: np.ndarray, assign: Assignment, origin: np.ndarray) -> np.ndarray | None:
    """A direction that points up: nasion, else upper lip, relative to ``origin``."""
    nasion = assign.references.get("nasion", ())
    for name in list(nasion) + [assign.roles.get("UL")]:
        if name is not None:
            p = med[assign.names.index(name)]
            if np.isfinite(p).all():
                return p - origin
    return None


def _role_median(med, assign, role):
    name = assign.roles.get(role)
    if name is None:
        return None
    p = med[assign.names.index(name)]
    return p if np.isfinite(p).all() else None


def _midline_plane(med: np.ndarray, assign: Assignment, extra=()) -> np.ndarray | None:
    points = [med[assign.names.index(s)] for s in assign.midline] + list(extra)
    found = head.fit_plane(np.array(points)) if len(points) >= 3 else None
    return None if found is None else found[0]


def _anatomy_2d(med, assign, origin) -> head.Frame:
    """2D data in unknown axes: each axis's sign from the anatomy."""
    forward, up = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    ul, ll = _role_median(med, assign, "UL"), _role_median(med, assign, "LL")
    back = next((p for r in _BACK_FIRST if (p := _role_median(med, assign, r)) is not None),
                None)
    signs = []
    if ul is not None and back is not None and ul[0] < back[0]:
        forward = -forward
        signs.append("x mirrored (the lips lie at -x)")
    if ul is not None and ll is not None and ul[1] < ll[1]:
        up = -up
        signs.append("y mirrored (the upper lip lies at -y)")
    source = ("the file's axes, signs from the anatomy" + (f": {'; '.join(signs)}" if signs
                                                              else "") +
              "; occlusal plane not given (the file's x axis stands for it)")
    return head.Frame(np.stack([forward, up]), origin, source)


def _occlusal_frame(where, raw: RawEma, corrected: _Corrected, assign: Assignment,
                    smap: SensorMap, bite: RawEma | None, scale: float,
                    bite_smap: SensorMap, placed: placement.Placement | None = None,
                    uncorrected: np.ndarray | None = None
                    ) -> tuple[head.Frame, list[str], placement.Placement | None]:
    """``uncorrected``: the positions in mm before head correction (default the file's)."""
    uncorrected = raw.positions * scale if uncorrected is None else uncorrected
    dims = raw.dims
    med = _median(corrected.positions)
    notes: list[str] = []
    ui = assign.upper_incisor
    ui_pos = med[assign.names.index(ui)] if ui is not None else None
    if ui_pos is not None and not np.isfinite(ui_pos).all():
        ui_pos = None
    origin = ui_pos if ui_pos is not None else np.zeros(dims)
    origin_words = (f"origin at the upper-incisor sensor {ui}" if ui_pos is not None
                    else "origin: the file's (no upper-incisor sensor)")
    if bite is not None:
        points, note = _bite_points(bite, bite_smap, corrected, (bite_smap.scale_mm or 1.0))
        if note:
            notes.append(note)
        lateral = None
        if dims == 3 and not ("left" in points and "right" in points):
            lateral = _midline_plane(med, assign, [points["front"], points["back"]])
            if lateral is None:
                raise DataFormatError(where, None, "bite plane without left/right sensors and "
                                      "too few midline sensors to find the midsagittal plane")
        frame = head.bite_frame(points["front"], points["back"],
                                _up_hint(med, assign, points["front"]),
                                left=points.get("left"), right=points.get("right"),
                                lateral=lateral, source=f"bite plane {bite.path or ''}".strip())
        if frame is None:
            raise DataFormatError(where, None, "bite-plane sensors are degenerate (front and "
                                  "back at one point, or left and right on the x axis)")
        return frame, notes, None
    if raw.frame == "mocha" and dims == 2:
        return head.Frame(np.array([[-1.0, 0.0], [0.0, 1.0]]), origin,
                          "MOCHA-TIMIT's documented axes (x toward the back: mirrored); "
                          f"{origin_words}; occlusal plane not given (the file's x axis "
                          "stands for it)"), notes, None
    if dims == 2 and smap.anterior is None and smap.origin is None:
        frame = _anatomy_2d(med, assign, origin)
        return head.Frame(frame.rotation, origin, f"{frame.source}; {origin_words}"), notes, None
    if placed is None:
        placed = _placement(where, [(corrected.positions, assign.names)], assign, smap,
                            corrected, uncorrected)
    return placed.frame, notes, placed


def _given(smap: SensorMap, dims: int, corrected: _Corrected | None, names,
           file_positions: np.ndarray | None) -> placement.Given:
    """The sensor map's frame facts in the head frame (mm)."""
    forward = up = origin = occlusal = None
    if smap.anterior is not None:
        forward = head.signed_axis(smap.anterior, dims)
        up = head.signed_axis(smap.up, dims)
        if abs(np.dot(forward, up)) > 0:
            raise DataFormatError(smap.name, None, "[file] anterior and up are the same axis")
    if smap.origin is not None:
        origin = np.asarray(smap.origin, float) * (smap.scale_mm or 1.0)
        if origin.shape[0] != dims:
            raise DataFormatError(smap.name, None, f"[file] origin has {origin.shape[0]} "
                                  f"numbers for {dims}D data")
        if corrected is not None and corrected.fits is not None and file_positions is not None:
            origin = _file_to_head(origin, corrected, names, file_positions)
    if isinstance(smap.occlusal_plane, tuple):
        occlusal = np.asarray(smap.occlusal_plane, float)[:dims]
    elif smap.occlusal_plane == "declared":
        occlusal = "declared"
    return placement.Given(origin=origin, occlusal=occlusal, forward=forward, up=up,
                           jaw_sensor=smap.jaw_sensor)


def _file_to_head(point: np.ndarray, corrected: _Corrected, names, file_positions: np.ndarray
                  ) -> np.ndarray:
    """A point given in the file's coordinates, in the head frame: moved as the median
    pose of the references (the head frame is their median configuration)."""
    index = [list(names).index(r) for r in corrected.references]
    refs = np.nanmedian(file_positions[:, index], axis=0)[None]
    fits = head.fit_references(refs, corrected.config, corrected.level)
    return fits.rotation[0] @ point + fits.translation[0]


def _placement(where, sessions, assign: Assignment, smap: SensorMap,
               corrected: _Corrected | None, file_positions) -> placement.Placement:
    dims = sessions[0][0].shape[2]
    given = _given(smap, dims, corrected, assign.names, file_positions)
    try:
        return placement.estimate_placement(sessions, assign.roles, sorted(assign.midline),
                                            given, upper_incisor=assign.upper_incisor)
    except placement.PlacementError as exc:
        raise DataFormatError(where, None, f"{exc}; {anatomy.GIVE}") from None


def _role_medians(track: PelletTrack) -> dict[str, np.ndarray]:
    out = {}
    for j, role in enumerate(PELLET_NAMES):
        ok = track.valid[:, j].all(-1)
        if ok.any():
            out[role] = np.median(track.positions[ok, j], axis=0)
    return out


def _check_roles(where, track: PelletTrack, assign: Assignment, frame: head.Frame,
                 placed: placement.Placement | None) -> None:
    """Maps that contradict the anatomy, sensors outside it (:mod:`~cassi_fit.ema.anatomy`)."""
    med = _role_medians(track)
    ui = assign.upper_incisor if (placed is None or "upper-incisor" in placed.source) else None
    tongue = [med[r][0] for r in ("T1", "T2", "T3", "T4") if r in med]
    if ("UL" in med and "LL" in med and med["UL"][1] < med["LL"][1]) or (
            "UL" in med and tongue and med["UL"][0] < np.mean(tongue)):
        return  # the axes are wrong, not the roles: the plausibility check says so
    anatomy.contradicted_roles(where, med, assign.roles, ui,
                               None if placed is None else placed.cues)
    if placed is not None or ui is not None:
        anatomy.outside_anatomy(where, med, assign.roles, frame.source)


def _check_anatomy(where, track: PelletTrack, frame: head.Frame) -> None:
    med = np.full((len(PELLET_NAMES), 2), np.nan)
    for j in range(len(PELLET_NAMES)):
        ok = track.valid[:, j].all(-1)
        if ok.any():
            med[j] = np.median(track.positions[ok, j], axis=0)
    found = med[np.isfinite(med).all(1)]
    if found.shape[0] >= 2:
        span = float(np.max(np.linalg.norm(found[:, None] - found[None], axis=-1)))
        lo, hi = SPAN_RANGE_MM
        if not lo <= span <= hi:
            raise DataFormatError(where, None, f"the sensors span {span:.3g} mm, not a head "
                                  f"({lo:.0f}-{hi:.0f} mm): are the units millimetres? (a "
                                  "sensor map's [file] scale_mm; normalised arrays need their "
                                  "means and SDs; docs/EMA.md)")
    problem = plausibility_problem(track)
    if problem is not None:
        raise DataFormatError(where, None, f"{problem} [occlusal frame: {frame.source}]; check "
                              "the sensor map's roles and [file] axes (docs/EMA.md)")


def ema_to_track(raw: RawEma, smap: SensorMap | str | os.PathLike | None = None, *,
                 bite: RawEma | None = None,
                 bite_map: SensorMap | str | os.PathLike | None = None, check: bool = True,
                 placement: placement.Placement | None = None
                 ) -> tuple[PelletTrack, SensorReport]:
    """The toolkit's pellet track of an articulograph recording, and how it was made
    (module docstring). ``smap``: a :class:`SensorMap`, a built-in map name, a ``.toml``
    path, or None (the built-in names); ``bite``: a bite-plane recording, read with
    ``bite_map`` (default ``smap``); ``check``: refuse implausible anatomy or units;
    ``placement``: the frame of the speaker's session (:func:`session_placement`), used
    instead of one estimated from this file alone."""
    smap = sensor_map(smap)
    proposal_notes: list[str] = []
    if smap.name == PROPOSED:
        smap, proposal_notes = proposed_map(raw)
    bite_smap = smap if bite_map is None else sensor_map(bite_map)
    where = raw.path
    scale = smap.scale_mm or 1.0
    assign = resolve(raw.names, smap, where)
    # dead channels, dropouts to zero, absurd values: untracked, never data (issue 28)
    positions, untracked_notes = untrack_impossible(raw.positions * scale, assign.names,
                                                    assign.reference_names)
    corrected = _correct(where, positions, assign,
                         None if placement is None else placement.head_config)
    frame, frame_notes, placed = _occlusal_frame(where, raw, corrected, assign, smap, bite,
                                                 scale, bite_smap, placement, positions)
    toolkit = frame.apply(corrected.positions)
    n = raw.n_frames
    index = {s: j for j, s in enumerate(assign.names)}
    pellets = np.full((n, len(PELLET_NAMES), 2), np.nan)
    for role, sensor in assign.roles.items():
        pellets[:, PELLET_NAMES.index(role)] = toolkit[:, index[sensor], :2]
    extras = toolkit[:, [index[s] for s in assign.extras], :2]
    pellet_valid = np.isfinite(pellets)
    pellet_valid &= pellet_valid.all(-1, keepdims=True)
    extra_valid = np.isfinite(extras)
    extra_valid &= extra_valid.all(-1, keepdims=True)
    track = PelletTrack(times=raw.times, positions=pellets, valid=pellet_valid, path=raw.path,
                        extra_names=assign.extras, extra_positions=extras,
                        extra_valid=extra_valid)
    if check:
        _check_roles(where, track, assign, frame, placed)
        _check_anatomy(where, track, frame)
    distances = {}
    if raw.dims == 3:
        med = _median(toolkit)
        distances = {s: float(med[j, 2]) for j, s in enumerate(assign.names)
                     if np.isfinite(med[j, 2])}
    fits = corrected.fits
    d = raw.dims
    if fits is not None:
        residual = fits.residual
        rotation = np.where(fits.ok, head.rotation_angle_deg(fits.rotation), np.nan)
        refs = positions[:, [index[r] for r in corrected.references]]
        centroid = head.tracked_mean(refs)
        shift = np.linalg.norm(centroid - corrected.config.mean(0), axis=-1)
        translation = np.where(fits.ok, shift, np.nan)
        lost = int((~fits.ok).sum())
    else:
        residual = rotation = translation = np.full(n, np.nan)
        lost = 0
    notes = (list(raw.notes) + untracked_notes + proposal_notes + list(assign.notes)
             + frame_notes)
    if lost:
        notes.append(f"{lost} frame(s) lack the reference sensors: their sensors are untracked")
    report = SensorReport(
        format=raw.format, rate_hz=float(raw.rate_hz), units=raw.units + (
            f"; times {smap.scale_mm:g} ([file] scale_mm)" if smap.scale_mm else ""),
        file_axes=raw.axes, dims=d, sensor_map=smap.name,
        roles={r: assign.roles.get(r) for r in PELLET_NAMES}, extras=assign.extras,
        references=corrected.references, head_correction=corrected.description,
        head_residual_mm=residual, head_rotation_deg=rotation,
        head_translation_mm=translation, frames_without_references=lost,
        frame_source=frame.source, frame_rotation=frame.rotation, frame_origin=frame.origin,
        midsagittal_distance_mm=distances,
        bite_plane=None if bite is None or bite.path is None else str(bite.path),
        notes=tuple(notes), head_fits=fits,
        placement=None if placed is None else placed.to_dict())
    return track, report


def session_placement(raws: Sequence[RawEma], smap: SensorMap | str | os.PathLike | None = None
                      ) -> placement.Placement:
    """One occlusal frame for the files of one speaker's session, estimated from all of
    them together (:mod:`cassi_fit.ema.placement`), to give each file's
    :func:`ema_to_track` (``placement=``). The files are head-corrected onto the first
    one's reference configuration, so that they share one head frame."""
    smap = sensor_map(smap)
    if smap.name == PROPOSED:
        smap, _ = proposed_map(list(raws))
    scale = smap.scale_mm or 1.0
    sessions, config, first = [], None, None
    for raw in raws:
        assign = resolve(raw.names, smap, raw.path)
        positions, _ = untrack_impossible(raw.positions * scale, assign.names,
                                          assign.reference_names)
        corrected = _correct(raw.path, positions, assign, config)
        config = corrected.config if config is None else config
        sessions.append((corrected.positions, assign.names))
        first = first or (raw, assign, corrected, positions)
    if first is None:
        raise ValueError("session_placement: no recordings")
    raw, assign, corrected, positions = first
    found = _placement(raw.path, sessions, assign, smap, corrected, positions)
    return dataclasses.replace(found, head_config=config,
                               head_references=tuple(corrected.references))


def proposed_map(raw) -> tuple[SensorMap, list[str]]:
    """The map :mod:`cassi_fit.ema.identify` proposes for ``raw`` (a file, or a session's
    files; the channels it is not sure of get no role), and notes saying so."""
    from .identify import propose_map
    from .sensor_map import builtin_map, numbered

    first = raw[0] if isinstance(raw, list | tuple) else raw
    if not numbered(first.names):
        return builtin_map("auto"), ["--accept-proposed-map: the channels have names, so "
                                     "the built-in names are used"]
    proposal = propose_map(raw)
    unsure = [f"{g.channel} ({g.role}?)" for g in proposal.guesses if not g.sure]
    notes = ["sensor map proposed from the data (--accept-proposed-map)"]
    if unsure:
        notes.append("not sure of, left without a role: " + ", ".join(unsure))
    return proposal.sensor_map(), notes + list(proposal.notes)


def session_of(paths, smap: SensorMap) -> tuple[SensorMap, placement.Placement | None]:
    """``(map, frame)`` of one speaker's session of articulograph files (``paths``), found
    from all of them together: the map proposed from the session when ``smap`` is
    ``"proposed"`` (files with different channels: each proposes its own), and
    :func:`session_placement` (None when it cannot be found: each file then finds its
    own, or says what it needs)."""
    from ..errors import CassiError
    from .detect import read_ema

    paths = list(paths)
    if not paths:
        return smap, None
    first = read_ema(paths[0])
    if first.dims == 2:  # midsagittal data: each file's own documented or anatomical axes
        return smap, None
    step = max(1, len(paths) // SESSION_FILES)  # a session's frame needs a sample, not all
    raws = [first] + [read_ema(p) for p in paths[step::step][:SESSION_FILES - 1]]
    if smap.name == PROPOSED:
        try:
            smap = proposed_map(raws)[0]
        except (CassiError, ValueError):
            pass
    try:
        return smap, session_placement(raws, smap)
    except (CassiError, ValueError):
        return smap, None
