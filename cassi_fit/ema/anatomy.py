"""Does a placed articulograph recording look like a head? Sensors inside the anatomy, and
sensor maps that contradict it.

Two checks on the CASSI roles' median positions in the toolkit's frame (mm, origin at
the upper incisor's tip, x forward along the occlusal plane, y up), each a one-line
:class:`~cassi_fit.errors.DataFormatError` naming the file:

* :func:`outside_anatomy`: a role whose median lies outside :data:`ANATOMY_BOX_MM` (boxes
  wide enough for every real speaker the toolkit has seen, with 10-20 mm to spare: the
  XRMB speaker JW11, the IPS Munich speaker mo1, the synthetic corpus): the frame is
  wrong, and the message says what to give (``[file] origin``, an upper-incisor sensor, a
  bite plane) instead of letting most frames be marked ``range`` mistracks or a face be
  drawn torn;
* :func:`contradicted_roles`: a map whose roles contradict the anatomy on any placement:
  tongue sensors out of their front-to-back order (tip and dorsum swapped), a jaw sensor
  (``MNI``) ahead of the lower lip's sensor (the jaw role on the lower lip), an
  upper-incisor reference lying ahead of the lower-incisor sensor by more than a lip's
  thickness (the reference on the upper lip), and the jaw sensor and the upper lip
  disagreeing about where the incisors are (:mod:`cassi_fit.ema.placement`'s cues). The
  message names the roles and their sensors.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import DataFormatError

#: Where each role's median may lie, toolkit frame (mm): ((x lo, x hi), (y lo, y hi)).
ANATOMY_BOX_MM = {
    "UL": ((-8.0, 40.0), (-15.0, 42.0)),
    "LL": ((-12.0, 40.0), (-65.0, 12.0)),
    "MNI": ((-22.0, 20.0), (-48.0, 12.0)),
    "MNM": ((-75.0, -12.0), (-45.0, 25.0)),
    **dict.fromkeys(("T1", "T2", "T3", "T4"), ((-105.0, 15.0), (-50.0, 45.0))),
}
#: Tongue sensors out of order by more than this (mm along x) contradict their roles.
TONGUE_ORDER_MARGIN_MM = 3.0
#: The upper-incisor reference may lie at most this far ahead of the lower-incisor sensor
#: (overjet plus the sensor's offset; a lip sensor lies 10-20 mm ahead).
INCISOR_AHEAD_MM = 9.0
#: Jaw and upper-lip origin cues farther apart than this many of their combined SDs.
CUES_APART_SD = 3.5
GIVE = ("give a bite-plane recording, an upper-incisor reference sensor, or the upper "
        "incisor's tip as [file] origin = [x, y, z] (the file's units and axes) in a sensor map")


def _fmt(p: np.ndarray) -> str:
    return f"({p[0]:.0f}, {p[1]:.0f}) mm"


def outside_anatomy(where, medians: Mapping[str, np.ndarray], sensors: Mapping[str, str],
                    frame_source: str) -> None:
    """Raise naming the roles whose median lies outside :data:`ANATOMY_BOX_MM`."""
    bad = []
    for role, p in medians.items():
        box = ANATOMY_BOX_MM.get(role)
        if box is None or not np.isfinite(p).all():
            continue
        (x0, x1), (y0, y1) = box
        if not (x0 <= p[0] <= x1 and y0 <= p[1] <= y1):
            bad.append(f"{role} ({sensors.get(role, '?')}) at {_fmt(p)}")
    if bad:
        raise DataFormatError(where, None, f"with the frame found ({frame_source.split(';')[0]})"
                              f" the sensors lie outside a head: {', '.join(bad)} from the "
                              f"upper incisor; {GIVE}")


def contradicted_roles(where, medians: Mapping[str, np.ndarray], sensors: Mapping[str, str],
                       upper_incisor: str | None = None,
                       cues: Mapping[str, object] | None = None) -> None:
    """Raise naming the roles of a sensor map that contradict the anatomy (module
    docstring); ``upper_incisor``: the reference's name when the origin is at it;
    ``cues``: a placement's cues (``origin_from_jaw_mm``, ``origin_from_upper_lip_mm``,
    ``origin_sd``)."""
    def name(role):
        return f"{role} = {sensors.get(role, '?')!r}"

    tongue = [r for r in ("T1", "T2", "T3", "T4") if r in medians]
    for i, a in enumerate(tongue):
        for b in tongue[i + 1:]:
            if medians[a][0] < medians[b][0] - TONGUE_ORDER_MARGIN_MM:
                raise DataFormatError(where, None, f"the sensor map's roles {name(a)} and "
                                      f"{name(b)} contradict the anatomy: {a} lies "
                                      f"{medians[b][0] - medians[a][0]:.0f} mm behind {b} "
                                      "(tongue sensors run front to back: swapped?)")
    if "MNI" in medians and "LL" in medians and medians["MNI"][0] > medians["LL"][0]:
        raise DataFormatError(where, None, f"the sensor map's roles {name('MNI')} and "
                              f"{name('LL')} contradict the anatomy: the jaw sensor lies "
                              f"{medians['MNI'][0] - medians['LL'][0]:.0f} mm ahead of the "
                              "lower lip's (is the jaw role on the lower lip?)")
    if upper_incisor is not None and "MNI" in medians and -medians["MNI"][0] > INCISOR_AHEAD_MM:
        raise DataFormatError(where, None, f"the sensor map's upper-incisor reference "
                              f"{upper_incisor!r} contradicts the anatomy: it lies "
                              f"{-medians['MNI'][0]:.0f} mm ahead of the jaw sensor "
                              f"({name('MNI')}), a lip's thickness (is it on the upper lip?)")
    if cues and "origin_from_jaw_mm" in cues and "origin_from_upper_lip_mm" in cues:
        jaw = np.asarray(cues["origin_from_jaw_mm"], float)
        lip = np.asarray(cues["origin_from_upper_lip_mm"], float)
        sd = np.asarray(cues.get("origin_cue_sd_mm", (3.0, 3.0)), float)
        apart = np.abs(jaw - lip) / sd
        if (apart > CUES_APART_SD).any():
            raise DataFormatError(where, None, f"the sensor map's roles {name('MNI')} and "
                                  f"{name('UL')} contradict the anatomy: they put the upper "
                                  f"incisor {np.linalg.norm(jaw - lip):.0f} mm apart (is the "
                                  "jaw role on the lower lip, the upper lip's on another "
                                  "sensor, or [file] jaw_sensor wrong?); if the roles are "
                                  "right, give the upper incisor's tip as [file] origin")
