"""CASSI's initialization: the face model fitted to one subject, once per recording.

Paper section 2; :func:`initialize`:

1. the first valid line (:func:`cassi_fit.pellets.first_valid_line`): the first frame in
   which every pellet the file ever tracks is tracked (a pellet the file never tracks
   stays at the model's rest site, flagged);
2. pellets to model: every coordinate scaled by ``p / d``, ``d = |MNI - MNM|`` of the
   subject in that frame, ``p`` the same distance between the model's jaw pellet sites.
   Both frames have their origin at the upper incisor tip, so no translation is needed.
   With one jaw sensor (most articulograph corpora: the lower incisor only) there is no
   ``d``: the scale is 1 (the data are in mm, the model is an adult's; a fitted
   calibration's scale when given), and the state says so (``SubjectState.jaw_sensors``);
3. the lower teeth and the jaw: the closed form (Eqs 1-3, 6-7, ``jaw.closed_form``) from
   the model's jaw sites to the scaled first-frame jaw pellets; with one jaw sensor, the
   translation that puts the model's incisor site on it (no rotation: one point cannot
   give one);
4. the pharyngeal wall from the scaled PHA.DAT (``pharynx.with_pharynx``; the model's
   default wall if absent), then the palate from the scaled PAL.DAT (``palate.with_palate``,
   joined to the model's upper teeth, its velum in front of the wall; the model's own
   centreline if absent, except for an articulograph recording outside CASSI mode: the
   default centreline's heights scaled to its tongue sensors' upper envelope,
   ``palate.envelope_palate``, said by ``cassi animate``);
5. the jaw's shape from the scaled Headmeasures gonion and gnathion against the model's
   gonion and gnathion, by the same closed form (``conformation.jaw_shape``);
6. beyond the paper (its future work): face and mouth width from Headmeasures, lip
   thickness per speaker, nose tip (``conformation.default_conformation``), or a fitted
   ``calibration.Calibration``; tongue (#55-#62) and lips (#63-#66) from the first frame.
   The model's lip sites are where the X-ray microbeam pellets sit on the lips; an
   articulograph lab glues its lip sensors elsewhere on the vermilion, so for an
   articulograph recording without a fitted calibration the lips are at rest where its
   first valid line has them (the report's and the calibration's assumption: the sensors'
   heights above the sites on that line, ``SubjectState.lip_rest``, said by ``cassi
   animate``), instead of being pushed into each other or apart by the placement; with
   the run's ``lip_closure`` (not the default) they touch instead where the lip sensors
   are nearest (``lips.lips_touching``).
   Likewise its tongue sensors are glued where the lab chose, not at XRMB's T1..T4 sites
   (IPS Munich's back sensor lies near the model's T4 site, not T3's): for an
   articulograph recording (not in CASSI mode) each tongue sensor is placed along the
   model's tongue by its distance from the one in front of it (the frontmost taken at its
   role's site: where it sits from the tongue's tip no sensor says), and the tongue is
   driven through each sensor at that point (``SubjectState.tongue_sites``,
   ``frames.tongue_drive``), said by ``cassi animate``.

Every choice of the run comes from one :class:`~cassi_fit.run_spec.RunSpec` (the
``"improved"`` or ``"cassi"`` preset, docs/CASSI_MODE.md, with any changes), checked once
where it is made; the state keeps it for the animation. The batched frame machinery is
:mod:`cassi_fit.frames`, shared with :mod:`cassi_fit.animate`; initialization does not
depend on animation. :func:`cassi_fit.pipeline.run_recording` runs both stages.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from .calibration import Calibration
from .conformation import default_conformation
from .dataset import Recording
from .errors import DegenerateGeometryError
from .face_model import FaceModel
from .frames import batch_geometry, frame_bucket, frame_params
from .jaw import closed_form_frames
from .pellets import LL, MNI, MNM, T1, T4, UL, first_valid_line
from .run_spec import RunSpec, run_spec


class SubjectState(eqx.Module):
    """The model fitted to one subject (the result of CASSI's initialization).

    model: the face model with the subject's palate. scale: ``p / d`` (model mm per
    subject mm). first_frame: index of the first valid data line. reference_jaw ``(2, 2)``
    mm: the scaled jaw pellets [MNI, MNM] of that line. initial_jaw: ``(theta rad,
    t (2,) mm)``, the closed-form motion from the model's jaw sites onto them.
    conformation: ``FaceParams`` of the subject's shape (jaw shape, widths, lip thickness,
    nose) with no animation; rest_pellets ``(8, 2)`` mm: the model's pellet sites in that
    shape, from which the tongue and lip parameters are measured (with a calibration, UL
    and LL raised by its ``lip_rest_offset``). initial_params: the parameters of the first
    valid frame. tracked_pellets: the names of the pellets the file ever tracks
    (``jaw_sensors``: the jaw pellets among them, ``("MNI",)`` for one jaw sensor).
    spec: the run's :class:`~cassi_fit.run_spec.RunSpec` (its calibration resolved for
    this subject); calibration: what the conformation came from (None: Headmeasures;
    ``"cassi"``; or the fitted ``Calibration``). source: the recording's name in messages.
    lip_rest: ``(upper, lower)`` model mm for an articulograph recording without a fitted
    calibration: how far above the model's UL and LL sites its lip sensors sit on the
    first valid line (step 6 of the module docstring), else None. tongue_sites: for an
    articulograph recording outside CASSI mode, the arc lengths (model mm from the
    tongue's tip along its upper midline) at which its T1..T4 sensors sit (None for a
    role no sensor plays), their ``rest_pellets`` rows the rest tongue's points there;
    else None (the sensors are the model's sites, as XRMB's pellets); tongue_note: the
    line saying where they were placed and what could not be measured. palate_note: the
    line saying the palate was estimated from the tongue sensors' upper envelope (step 4),
    else None. lip_note: the line saying ``lip_rest`` was set where the lip sensors are
    nearest, the lips touching there (``lips.lips_touching``), else None.
    """

    model: eqx.Module
    scale: float = eqx.field(static=True)
    first_frame: int = eqx.field(static=True)
    reference_jaw: jax.Array
    initial_jaw: tuple
    conformation: eqx.Module
    rest_pellets: jax.Array
    initial_params: eqx.Module
    tracked_pellets: tuple = eqx.field(static=True)
    source: str = eqx.field(static=True)
    spec: RunSpec = eqx.field(static=True)
    calibration: object = eqx.field(static=True, default=None)
    lip_rest: tuple | None = eqx.field(static=True, default=None)
    tongue_sites: tuple | None = eqx.field(static=True, default=None)
    tongue_note: str | None = eqx.field(static=True, default=None)
    palate_note: str | None = eqx.field(static=True, default=None)
    lip_note: str | None = eqx.field(static=True, default=None)

    @property
    def calibration_problems(self) -> tuple[str, ...]:
        """What is wrong with the fitted calibration used (``Calibration.problems``: a fit
        that did not converge, a bound reached, an implausible value), one line each;
        empty without one or when it is fine."""
        cal = self.calibration
        return tuple(cal.problems()) if isinstance(cal, Calibration) else ()

    @property
    def calibration_caveats(self) -> tuple[str, ...]:
        """The limits every fitted calibration has, with their size
        (``Calibration.caveats``: the lower lip's unobservable offset, ...), and where the
        lip sensors' rest was taken from the first valid line (:attr:`lip_rest`)."""
        cal = self.calibration
        out = tuple(cal.caveats()) if isinstance(cal, Calibration) else ()
        if self.lip_note is not None:
            out += (self.lip_note,)
        elif self.lip_rest is not None:
            out += (f"the lip sensors sit {self.lip_rest[0]:+.1f} mm (upper) and "
                    f"{self.lip_rest[1]:+.1f} mm (lower) above the model's lip sites on the "
                    f"first valid line ({self.first_frame + 1}), taken as the lips at rest "
                    "(an articulograph's lip sensors are glued elsewhere than the X-ray "
                    "microbeam pellets the model's sites stand for)",)
        if self.tongue_note is not None:
            out += (self.tongue_note,)
        if self.palate_note is not None:
            out += (self.palate_note,)
        return out

    @property
    def jaw_sensors(self) -> tuple[str, ...]:
        """The jaw pellets the recording tracks, ``("MNI", "MNM")`` or one of them."""
        return tuple(p for p in ("MNI", "MNM") if p in self.tracked_pellets)

    # the run's choices, read from the spec (one home)
    @property
    def mode(self) -> str:
        return self.spec.mode

    @property
    def jaw_weights(self) -> str:
        return self.spec.jaw_weights

    @property
    def tongue_anchor(self) -> str:
        return self.spec.tongue_anchor

    @property
    def tongue_shape(self) -> str:
        return self.spec.tongue_shape

    @property
    def lip_rounding(self) -> bool:
        return self.spec.lip_rounding

    @property
    def gap_policy(self) -> str:
        return self.spec.gap_policy


def _scale(model, pellets: Float[np.ndarray, "8 2"], source: str, first: int) -> float:
    """``p / d`` (step 2), or ``DegenerateGeometryError`` for coincident jaw pellets."""
    from .deform import model_pellets

    d = float(np.linalg.norm(pellets[MNI] - pellets[MNM]))
    sites = model_pellets(model, np.asarray(model.vertices))  # numpy: nothing compiled
    if not d > 0.0:
        raise DegenerateGeometryError(
            f"{source}: MNI and MNM coincide on the first valid line ({first + 1})"
        )
    return float(np.linalg.norm(sites[MNI] - sites[MNM])) / d


def _rest_pellets(model, conformation, spec):
    """The model's vertices ``(V, 3)`` and pellet sites ``(8, 2)`` mm in the subject's
    shape, by the batched geometry at its smallest frame bucket (``frame_bucket(1)``): one
    compilation serves every recording, whatever its length (the same in every row)."""
    size = frame_bucket(1)
    batch = jax.tree.map(lambda x: _rows(x, size), conformation)
    vertices, sites = batch_geometry(model, batch, **spec.deform_style)
    return vertices[0], sites[0]


def _tongue_sensor_sites(model, vertices, track, tracked, scale, roles) -> tuple:
    """Where an articulograph's tongue sensors sit on the model's tongue (step 6):
    ``(sites, points, note)``. ``sites``: per role T1..T4 the arc length (model mm from
    the tongue's tip along its upper midline) or None; ``points (4, 2)``: the rest
    tongue's upper midline there (``vertices (V, 3)`` the model at rest; NaN for None);
    ``note``: one line saying so. The frontmost sensor is taken at its role's site; each
    next one lies its median distance (over the frames tracking both, times ``scale``)
    farther along: the chord, a little less than the arc between them."""
    from .deform import tongue_points_at, tongue_site_arcs

    names = ("T1", "T2", "T3", "T4")
    have = [k for k, r in enumerate(names) if r in tracked]
    if not have:
        return None, None, None
    site_s = tongue_site_arcs(model)
    pos = np.asarray(track.positions, np.float64)[:, T1:T4 + 1]
    ok = np.asarray(track.valid)[:, T1:T4 + 1].all(-1)
    sites = [None] * 4
    sites[have[0]] = float(site_s[have[0]])
    for a, b in zip(have, have[1:], strict=False):
        both = ok[:, a] & ok[:, b]
        sites[b] = sites[a] + scale * float(np.median(np.linalg.norm(
            pos[both, b] - pos[both, a], axis=1)))
    points = np.full((4, 2), np.nan)
    points[have] = tongue_points_at(model, vertices, [sites[k] for k in have])
    sensor = [roles.get(names[k]) or names[k] for k in have]
    label = [f"{name} ({names[k]})" for name, k in zip(sensor, have, strict=True)]
    where = ", ".join(f"{sites[k]:.1f}" for k in have)
    model_sites = ", ".join(f"{x:.1f}" for x in site_s)
    if len(have) == 1:
        note = (f"the tongue sensor {label[0]} is taken at the model's {names[have[0]]} site "
                f"({where} mm from the tongue's tip): with one tongue sensor where it sits on "
                "the tongue cannot be measured")
    else:
        note = (f"the tongue sensors {', '.join(label)} are placed {where} mm from the "
                f"tongue's tip along the model's tongue (its T1-T4 sites: {model_sites} mm) "
                "by their median distances apart, and the tongue is driven through each "
                f"there; {sensor[0]} is taken at the {names[have[0]]} site (where "
                "it sits from the tip no sensor says)")
    return tuple(sites), points, note


def _tongue_at_sensors(model, spec, recording, rest_vertices, rest, tracked, scale):
    """``(rest, tongue_sites, tongue_note)``: for an articulograph recording outside
    CASSI mode, its tongue sensors placed on the model's tongue
    (:func:`_tongue_sensor_sites`) and the rest sites' T1..T4 rows moved there; else
    ``rest`` unchanged and None, None (XRMB's pellets are the model's sites)."""
    if spec.mode == "cassi" or getattr(recording, "sensors", None) is None:
        return rest, None, None
    sites, points, note = _tongue_sensor_sites(model, rest_vertices, recording.track,
                                               tracked, scale, dict(recording.sensors.roles))
    if sites is not None:
        have = np.array([x is not None for x in sites])
        rest = rest.at[T1:T4 + 1].set(jnp.where(
            jnp.asarray(have)[:, None], jnp.asarray(np.nan_to_num(points), rest.dtype),
            rest[T1:T4 + 1]))
    return rest, sites, note


def _rows(x, size: int) -> jax.Array:
    """``x`` repeated as ``size`` rows (a leading axis); a concrete array in numpy, which
    compiles nothing (``jnp.broadcast_to`` compiles a copy per shape)."""
    if isinstance(x, jax.core.Tracer):
        return jnp.broadcast_to(x, (size, *jnp.shape(x)))
    return jax.device_put(np.broadcast_to(np.asarray(x), (size, *np.shape(x))).copy())


def _first_row(x) -> jax.Array:
    """The first row of ``x`` (in numpy when concrete: nothing compiled)."""
    if isinstance(x, jax.core.Tracer):
        return x[0]
    return jax.device_put(np.asarray(x)[0].copy())


def _lips_at_rest(rest, offset) -> jax.Array:
    """``rest`` with the UL and LL sites raised by ``offset`` (upper, lower) model mm: the
    lips' vertical rest where the lip pellets sit (a calibration's ``lip_rest_offset``)."""
    return rest.at[UL, 1].add(offset[0]).at[LL, 1].add(offset[1])


def _first_line_lips(model, spec, rest, initial_jaw, scaled) -> tuple[float, float]:
    """``(upper, lower)`` model mm: how far above the model's UL and LL sites the lip
    sensors sit on the first valid line ``scaled (8, 2)`` (the lower one after the model's
    jaw is placed there by ``initial_jaw``), as a calibration's ``lip_rest_offset``; 0 for
    a lip the recording does not track."""
    from . import rigid

    w_ll = jnp.asarray(model.jaw_weights[spec.jaw_weights])[model.landmarks["LL"]]
    ll = rigid.apply(*rigid.fractional(initial_jaw, w_ll), rest[LL])
    up, low = float(scaled[UL, 1] - rest[UL, 1]), float(scaled[LL, 1] - ll[1])
    return (up if np.isfinite(up) else 0.0, low if np.isfinite(low) else 0.0)


def _lips_touching(model, vertices, rest, lip_rest, recording, scale) -> tuple:
    """``(lip_rest, lip_note)``: the first line's ``lip_rest`` moved so that the model's
    lips touch where the lip sensors are nearest (``lips.lips_touching``); unchanged and
    None when the recording has no such distance."""
    from .lips import lips_touching

    found = lips_touching(model, vertices, rest, lip_rest, recording.track, scale,
                          getattr(recording, "labels", ()))
    return found if found is not None else (lip_rest, None)


def _initial_jaw(rest, reference, tracked) -> tuple:
    """Step 3: ``(theta, t)`` from the model's jaw sites ``rest[[MNI, MNM]]`` onto the
    first line's scaled jaw pellets ``reference (2, 2)``: the closed form with both; with
    one jaw sensor, the translation of its site onto it (theta 0)."""
    if "MNI" in tracked and "MNM" in tracked:
        if isinstance(rest, jax.core.Tracer) or isinstance(reference, jax.core.Tracer):
            motion = closed_form_frames(rest[jnp.array([MNI, MNM])], reference[None])
        else:  # the inputs picked out in numpy: only the closed form is compiled
            motion = closed_form_frames(np.asarray(rest)[[MNI, MNM]],
                                        np.asarray(reference)[None])
        return _first_row(motion.theta), _first_row(motion.translation)
    k = MNI if "MNI" in tracked else MNM
    return jnp.zeros((), reference.dtype), reference[k - MNI] - rest[k]


def _subject_model(model, recording, scale, spec):
    """``(model, palate_note)``: the face model with the subject's pharyngeal wall and
    palate (step 4); for an articulograph recording without a palate trace outside CASSI
    mode, the palate from its tongue sensors' upper envelope and the line saying so
    (``palate.envelope_palate``), else None."""
    from .palate import DEFAULT_OUTLINE, envelope_palate, with_palate
    from .pharynx import has_pharynx, with_pharynx

    pharynx = getattr(recording, "pharynx", None)
    if pharynx is not None and has_pharynx(model):
        model = with_pharynx(model, scale * np.asarray(pharynx, np.float64))
    if recording.palate is not None:
        return with_palate(model, scale * np.asarray(recording.palate, np.float64)), None
    sensors = getattr(recording, "sensors", None)
    found = None if spec.mode == "cassi" or sensors is None else envelope_palate(
        recording.track, dict(sensors.roles), scale)
    if found is not None:
        return with_palate(model, found[0]), found[1]
    if pharynx is not None and has_pharynx(model):  # the velum in front of this wall
        model = with_palate(model, DEFAULT_OUTLINE)
    return model, None


def initialize(
    recording: Recording,
    model: FaceModel | None = None,
    *,
    spec: RunSpec | None = None,
    **changes: object,
) -> SubjectState:
    """Fit the face model to the subject of ``recording`` (CASSI's initialization).

    ``recording``: a ``dataset.Recording``. ``model``: a ``FaceModel`` (default
    ``load_model()``). ``spec``: the run's :class:`~cassi_fit.run_spec.RunSpec` (default:
    the ``"improved"`` preset); ``changes``: fields of the spec to change, by name
    (``mode="cassi"``, ``calibration=...``, ``tongue_shape="flat"``, ...; see
    :func:`cassi_fit.run_spec.run_spec`). The calibration is resolved for this subject
    (``RunSpec.calibration_for``): None (the subject's shape from its Headmeasures and
    first valid line, step 6 of the module docstring), ``"cassi"`` (only what the paper
    did: the jaw shape from gonion and gnathion), or a fitted
    :class:`~cassi_fit.calibration.Calibration` of this subject (its scale and shape;
    ``cassi calibrate``). Returns a :class:`SubjectState`. Raises ``MissingDataError`` (jaw
    pellets never tracked), ``DegenerateGeometryError`` (coincident jaw pellets on the
    first valid line), ``InvalidChoiceError`` (an unknown option) or ``CassiError`` (a
    calibration of another subject, or a fitted calibration in the ``"cassi"`` mode).
    """
    from .face_model import load_model

    mode = changes.pop("mode", None)
    if spec is not None and mode is not None:
        spec = spec.replace(mode=mode)
    spec = run_spec(spec if spec is not None else mode, **changes)
    calibration = spec.calibration_for(recording.subject)
    fitted = calibration if isinstance(calibration, Calibration) else None
    source = recording.source
    model = load_model() if model is None else model
    track = recording.track
    first, tracked = first_valid_line(track, source)
    pellets = np.asarray(track.positions[first], np.float64)  # (8, 2) mm, subject
    both = "MNI" in tracked and "MNM" in tracked
    if fitted is not None:
        scale = float(fitted.scale)
    else:  # one jaw sensor: no p / d; the data are in mm (module docstring, step 2)
        scale = _scale(model, pellets, source, first) if both else 1.0
    model, palate_note = _subject_model(model, recording, scale, spec)
    if fitted is not None:
        conformation = fitted.face_params(jnp.asarray(model.vertices).dtype)
    else:
        conformation = default_conformation(model, recording, pellets, scale,
                                            calibration or "measures")
    # the first line's parameters at the batch size animate() uses for every line of this
    # recording (stride 1), so that both share one compilation
    size = frame_bucket(track.times.shape[0] - first)
    rest_vertices, rest = _rest_pellets(model, conformation, spec)
    reference = jnp.asarray(scale * pellets[[MNI, MNM]])  # NaN for a jaw pellet not tracked
    initial_jaw = _initial_jaw(rest, reference, tracked)
    lip_rest, lip_note = None, None
    if fitted is not None:  # the lips' vertical rest where the first valid lines have them
        rest = _lips_at_rest(rest, fitted.lip_rest_offset)
    elif calibration is None and getattr(recording, "sensors", None) is not None:
        # an articulograph's lip sensors: the same rest, from this recording's first line
        lip_rest = _first_line_lips(model, spec, rest, initial_jaw, scale * pellets)
        if spec.lip_closure:  # not the default: docs/ACOUSTICS.md, the lips touching
            lip_rest, lip_note = _lips_touching(model, rest_vertices, rest, lip_rest,
                                                recording, scale)
        rest = _lips_at_rest(rest, lip_rest)
    rest, tongue_sites, tongue_note = _tongue_at_sensors(
        model, spec, recording, rest_vertices, rest, tracked, scale)
    state = SubjectState(
        model=model, scale=scale, first_frame=first, reference_jaw=reference,
        initial_jaw=initial_jaw, conformation=conformation,
        rest_pellets=rest, initial_params=conformation, tracked_pellets=tracked,
        source=source, spec=spec, calibration=calibration, lip_rest=lip_rest,
        tongue_sites=tongue_sites, tongue_note=tongue_note, palate_note=palate_note,
        lip_note=lip_note,
    )  # fmt: skip
    first_params = frame_params(
        state, np.broadcast_to(scale * pellets, (size, 8, 2)), np.zeros(size), np.zeros((size, 2))
    )
    first_params = jax.tree.map(_first_row, first_params)
    return eqx.tree_at(lambda s: s.initial_params, state, first_params)
