"""Channels without names identified from the data: a proposed sensor map.

Articulographs export channels as numbers (AG500/AG501 ``Ch1..Ch16``, Wave sensor ids).
:func:`propose_map` looks at what each channel does and proposes its role, with the
evidence and a confidence in [0, 1]; a guess under :data:`SURE` is marked *not sure*. In
order:

1. **unused**: never tracked, or exactly constant;
2. **head references**: the candidates are the groups of channels rigid among themselves
   (the 95 % range of every pairwise distance under :data:`RIGID_SD_MM`) spanning a skull
   (two of them more than :data:`SKULL_MM` apart: a jaw's two sensors are closer), but
   for a group that leaves no mouth: with it as the head, the two channels taken for the
   lips (step 4) would lie more than :data:`LIPS_APART_MM` apart (a jaw that barely moves
   can be as rigid to two mastoid references as a loose nasion reference is); the most
   rigid is kept, and the other channels are corrected for head movement with it
   (:mod:`cassi_fit.ema.head`);
3. **the midline**: the plane through the moving channels; a channel whose median lies
   more than 8 mm from it is *parasagittal* (a lip corner, a lateral tongue sensor) and
   gets no role;
4. within the plane: the **lips** are the end of the midline where the two front-most
   channels lie far apart across it (the tongue's end is a chain of sensors along it);
   the **upper lip** is the one of the two that moves less (the lower lip rides on the
   jaw); the **jaw sensor** is the next channel from the front, moving with the lower
   lip; a channel **rigid to it** 25-65 mm away, more than 20 mm behind it, is the
   second jaw sensor; the rest are
   the **tongue**, front to back ``T1..T4`` (more than four: the extra back ones get none);
5. **the same with every rival head group**: steps 3-4 rest on the head correction, and the
   kept group may be the wrong one (a loose reference varies nearly as much as the jaw
   against two mastoid references). So they are done again with each rival: every other
   candidate group, and, when the evidence does not rule it out at :data:`SURE`, the group
   without a member not clearly rigid to the others (``none``: no correction, when the rest
   spans no skull) or with a channel outside it nearly rigid to it. A channel's role found
   with every rival keeps its own confidence (the lowest with the kept group and the
   rivals not ruled out); one that changes is capped at the head group's confidence:
   nothing is surer than the head correction it rests on. The references keep the head
   group's confidence, but for one that every rival group holds too and that lies far
   from the mouth: it is a reference whichever group is the head (its role the same under
   every rival), so it keeps its own, from its rigidity to the other members.

Nothing here is used unless asked: ``cassi info --write-sensor-map FILE`` writes the
proposal as an editable TOML sensor map; ``--accept-proposed-map`` (every command) uses
it, leaving the channels it is not sure of without a role.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import head, placement
from ._raw import RawEma

#: A guess at or above this confidence is "sure".
SURE = 0.9
#: Channels whose pairwise distances vary less than this (2.5-97.5 percentile range, mm)
#: are rigid.
RIGID_SD_MM = 3.0
#: A rigid group with two members farther apart than this spans a skull, not a jaw.
SKULL_MM = 80.0
#: A second jaw sensor's distance to the first varies less than this (mm, 95 % range).
JAW_RIGID_MM = 1.5
#: A channel within this distance (median, mm) of an articulator lies near the mouth.
MOUTH_MM = 25.0
#: The lip sensors' median distance across the midline (mm) is below this in speech: each
#: sits on its vermilion (upper about 8-9 mm high, lower 9-10 mm, Farkas 1994), and the
#: lips' median opening in speech is well under the 50 mm of a maximal jaw opening
#: (Gallagher et al. 2004); a head group under which the lips would lie farther apart
#: leaves no mouth and is not the head.
LIPS_APART_MM = 45.0
_MAX_FRAMES = 3000


@dataclass(frozen=True)
class Guess:
    """One channel's proposed role: ``role`` a CASSI role (``UL``...), ``"reference"``,
    ``"parasagittal"``, ``"unused"`` or ``"extra"``; ``confidence`` in [0, 1];
    ``evidence`` in words."""

    channel: str
    role: str
    confidence: float
    evidence: str

    @property
    def sure(self) -> bool:
        return self.confidence >= SURE


@dataclass(frozen=True)
class Proposal:
    """A proposed sensor map: one :class:`Guess` per channel, in file order."""

    guesses: tuple[Guess, ...]
    notes: tuple[str, ...] = field(default=())

    def role_of(self, channel: str) -> str:
        return next(g.role for g in self.guesses if g.channel == channel)

    def to_toml(self, source: str = "") -> str:
        """The proposal as a TOML sensor map (:mod:`cassi_fit.ema.sensor_map`), each line
        with its confidence and evidence; the channels it is not sure of are commented out."""
        lines = ["# Sensor map proposed by cassi_fit from the data" + (f" of {source}" if source
                                                                       else ""),
                 "# (cassi info --write-sensor-map). Check every line; lines marked NOT SURE",
                 "# are commented out: give them a name yourself.", "[channels]"]
        refs = []
        for i, g in enumerate(self.guesses, start=1):
            name = _name(g, i)
            if g.role == "reference":
                refs.append(name)
            mark = "" if g.sure else "# NOT SURE: "
            lines.append(f'{mark}{i} = "{name}"   # {g.channel}: {g.role}, confidence '
                         f"{g.confidence:.2f}: {g.evidence}")
        lines += ["", "[references]", "sensors = [" + ", ".join(f'"{r}"' for r in refs
                                                                 if self._sure_name(r)) + "]"]
        return "\n".join(lines) + "\n"

    def _sure_name(self, name: str) -> bool:
        return any(_name(g, i) == name and g.sure for i, g in enumerate(self.guesses, 1))

    def sensor_map(self, name: str = "proposed"):
        """The proposal as a :class:`~cassi_fit.ema.sensor_map.SensorMap` (the channels it
        is not sure of keep their numbers and get no role)."""
        from .sensor_map import SensorMap

        channels = {i: _name(g, i) for i, g in enumerate(self.guesses, 1) if g.sure}
        refs = tuple(_name(g, i) for i, g in enumerate(self.guesses, 1)
                     if g.sure and g.role == "reference")
        return SensorMap(channels=channels, references=refs, name=name)


def _name(g: Guess, i: int) -> str:
    if g.role in ("reference", "parasagittal", "unused", "extra"):
        return {"reference": "REF", "parasagittal": "PARA", "unused": "UNUSED",
                "extra": "EXTRA"}[g.role] + str(i)
    return g.role


def _conf(margin: float, scale: float) -> float:
    """A confidence from a margin (0 at no margin, 0.9 at ``scale``)."""
    return float(1.0 - np.exp(-max(margin, 0.0) / scale * np.log(10.0)))


def _robust_sd(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    if v.size < 10:
        return np.inf
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


# ------------------------------------------------------------------ steps
def _unused(pos: np.ndarray, names) -> dict[str, Guess]:
    out = {}
    for j, name in enumerate(names):
        ok = np.isfinite(pos[:, j]).all(-1)
        if ok.mean() < 0.02:
            out[name] = Guess(name, "unused", 1.0, f"tracked on {ok.sum()} of {ok.size} frames")
        elif np.ptp(pos[ok, j], axis=0).max() == 0.0:
            out[name] = Guess(name, "unused", 0.97, "exactly constant (a channel with no coil)")
    return out


def _rigidity(pos: np.ndarray, a: int, b: int) -> tuple[float, float]:
    """How much the distance between channels ``a`` and ``b`` varies (its 2.5-97.5
    percentile range, mm; inf with too few common frames) and its median."""
    d = np.linalg.norm(pos[:, a] - pos[:, b], axis=-1)
    d = d[np.isfinite(d)]
    if d.size < 10:
        return np.inf, np.nan
    lo, mid, hi = np.percentile(d, [2.5, 50, 97.5])
    return float(hi - lo), float(mid)


def _head_group(pos: np.ndarray, idx: list[int], mouth=None
                ) -> tuple[list[int], float, str, dict[tuple[int, ...], bool]]:
    """The head references among channels ``idx``: ``(members, confidence, each
    member's confidence (:func:`_held`), evidence, rivals)``.

    Candidates are the groups of channels rigid among themselves spanning a skull; the
    most rigid is kept (a jaw's sensors can be nearly rigid with two mastoid references,
    the jaw turning about an axis near them: about 1 mm, where skull references vary by
    their noise), its confidence lowered when another group comes close. ``rivals`` maps
    the other head groups to whether the evidence leaves them open (does not rule them out
    at :data:`SURE`; each such one lowered the confidence under it): every other candidate
    (open when nearly as rigid), and, open, the group without a member whose distance to
    another varies nearly as much as :data:`RIGID_SD_MM` (a loose reference, or not a
    reference at all; ``()`` when the rest spans no skull) and the group with a channel
    outside it rigid to it nearly within :data:`RIGID_SD_MM`. ``mouth``: a function of a
    group (channel indices) giving how far apart the lips would lie with it as the head
    (:func:`_lips_apart`); a group whose lips would lie more than :data:`LIPS_APART_MM`
    apart is neither kept nor a rival (unless every candidate is such a group)."""
    k = len(idx)
    sd = np.full((k, k), np.inf)
    dist = np.zeros((k, k))
    for i in range(k):
        for j in range(i + 1, k):
            sd[i, j], dist[i, j] = _rigidity(pos, idx[i], idx[j])
            sd[j, i], dist[j, i] = sd[i, j], dist[i, j]
    groups = set()
    for seed in range(k):  # greedy cliques of rigid channels
        group = [seed]
        for j in np.argsort(sd[seed]):
            if j not in group and all(sd[j, g] < RIGID_SD_MM for g in group):
                group.append(int(j))
        if len(group) >= 2 and _span(dist, group) > SKULL_MM:
            groups.add(tuple(sorted(group)))
    if not groups:
        return [], 1.0, {}, "", {}
    groups = {_trimmed(sd, dist, g) for g in groups}

    def mouthless(g) -> bool:
        return mouth is not None and bool(g) and mouth(tuple(idx[j] for j in g)) > LIPS_APART_MM

    groups = {g for g in groups if not mouthless(g)} or groups
    scored = sorted((_worst(sd, g), -len(g), g) for g in groups)
    worst, _, best = scored[0]
    best = _extended(sd, dist, best)
    worst = _worst(sd, best)
    scored = [t for t in scored if not (set(t[2]) <= set(best) or set(t[2]) >= set(best))]
    scored.insert(0, (worst, -len(best), best))
    others = [j for j in range(k) if j not in best]
    nearest = min((max(sd[j, g] for g in best) for j in others), default=np.inf)
    conf = min(_conf(RIGID_SD_MM - worst, 1.0), _conf(nearest - RIGID_SD_MM, 1.0))
    words = ""
    if len(scored) > 1:
        conf = min(conf, _conf(scored[1][0] - worst, 0.8))
        words = (f"; the next most rigid group of channels spanning a skull varies by "
                 f"{scored[1][0]:.1f} mm")
    rivals: dict[tuple[int, ...], bool] = {}  # group -> left open at SURE
    for t in scored[1:]:  # every other candidate
        rivals[_extended(sd, dist, t[2])] = _conf(t[0] - worst, 0.8) < SURE
    for m in best:  # a member not rigid to another beyond doubt: the group without it
        if any(_conf(RIGID_SD_MM - sd[m, g], 1.0) < SURE for g in best if g != m):
            rest = tuple(g for g in best if g != m)
            rivals[rest if len(rest) >= 2 and _span(dist, rest) > SKULL_MM else ()] = True
    for j in others:  # a channel nearly rigid to the group: the group with it
        if _conf(max(sd[j, g] for g in best) - RIGID_SD_MM, 1.0) < SURE:
            rivals[tuple(sorted(best + (j,)))] = True
    rivals = {r: p for r, p in rivals.items() if not mouthless(r)}
    own = {idx[m]: _held(sd, dist, best, m, rivals, conf, nearest) for m in best}
    rivals = {tuple(idx[j] for j in r): p for r, p in rivals.items()}
    return [idx[j] for j in best], conf, own, (
        f"rigid among themselves (their distances vary by at most {worst:.1f} mm, span "
        f"{_span(dist, best):.0f} mm); every other channel's by {nearest:.1f} mm or "
        f"more{words}"), rivals


def _held(sd, dist, best, m, rivals, conf, nearest) -> float:
    """Member ``m``'s confidence as a reference: the head group's, or, when every rival
    head group holds it too and it lies far from the mouth, its own (its distances to the
    other members varying within :data:`RIGID_SD_MM`, and no other channel nearly rigid
    to the group): it is a reference whichever group is the head, as a role the same
    under every rival keeps its own confidence (step 5)."""
    if not rivals or not all(m in r for r in rivals) or _near_mouth(dist, m, best):
        return conf
    own = min(_conf(RIGID_SD_MM - max(sd[m, g] for g in best if g != m), 1.0),
              _conf(nearest - RIGID_SD_MM, 1.0))
    return max(conf, own)


def _span(dist: np.ndarray, group) -> float:
    """The largest distance (median, mm) between two channels of ``group``."""
    return max((dist[a, b] for a in group for b in group), default=0.0)


def _near_mouth(dist: np.ndarray, member: int, group) -> bool:
    """True when ``member`` lies within :data:`MOUTH_MM` of a channel outside ``group``
    (the articulators): a jaw sensor, not a skull reference (an upper-incisor reference,
    though near, is rigid to the skull within its noise and is never trimmed)."""
    return any(dist[member, j] < MOUTH_MM for j in range(dist.shape[0])
               if j != member and j not in group)


def _trimmed(sd: np.ndarray, dist: np.ndarray, group: tuple[int, ...]) -> tuple[int, ...]:
    """``group`` without a member that moves against the others (an upper lip that barely
    moves in a task, a jaw sensor turning about an axis near two mastoid references):
    dropped when its distances vary more than 0.5 mm and twice as much as the rest's, and
    the rest keep three members, or two spanning a skull when it lies near the mouth."""
    group = tuple(group)
    for m in sorted(group, key=lambda m: -max(sd[m, g] for g in group if g != m)):
        rest = tuple(g for g in group if g != m)
        if (len(rest) >= 2 and max(sd[m, g] for g in rest) > 0.5 and _near_mouth(dist, m, group)
                and _span(dist, rest) > SKULL_MM):
            group = rest  # a sensor near the mouth that moves against the skull: the jaw
    while len(group) > 2:
        worst_member = max(group, key=lambda m: max(sd[m, g] for g in group if g != m))
        rest = tuple(g for g in group if g != worst_member)
        own = max(sd[worst_member, g] for g in rest)
        enough = len(rest) >= 3 or (_near_mouth(dist, worst_member, group)
                                    and _span(dist, rest) > SKULL_MM)
        if own > 0.5 and own > 2.0 * _worst(sd, rest) and enough:
            group = rest
        else:
            break
    return tuple(sorted(group))


def _extended(sd: np.ndarray, dist: np.ndarray, group: tuple[int, ...]) -> tuple[int, ...]:
    """``group`` with every other channel rigid to it (within :data:`RIGID_SD_MM`) that
    lies far from the mouth: a loose skull reference."""
    out = list(group)
    for j in range(sd.shape[0]):
        if j not in out and max(sd[j, g] for g in out) < RIGID_SD_MM and not _near_mouth(
                dist, j, out + [j]):
            out.append(j)
    return tuple(sorted(out))


def _worst(sd: np.ndarray, group) -> float:
    return max((sd[a, b] for a in group for b in group if a != b), default=np.inf)


def _corrected(pos: np.ndarray, refs: list[int]) -> np.ndarray:
    if not refs:
        return pos
    level = head.reference_level(pos.shape[2], len(refs))
    config = head.reference_configuration(pos[:, refs], level)
    if config is None:
        return pos
    return head.apply(head.fit_references(pos[:, refs], config, level), pos)


def _series2(pos, j, centre, e1, e2) -> np.ndarray:
    p = pos[:, j] - centre
    return np.stack([p @ e1, p @ e2], -1)


def _range(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    return float(np.ptp(np.percentile(v, [5, 95]))) if v.size else 0.0


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 10 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return 0.0
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def _pair_spread(points: np.ndarray) -> float:
    """The largest separation across the axis (y) of two of ``points`` (k, 2)."""
    return max((abs(p[1] - q[1]) for i, p in enumerate(points) for q in points[i + 1:]),
               default=0.0)


def _front_and_up(med, series, mids):
    """Forward and up from the lips: ``(s1, conf, words, upper, lower, conf_up, words)``.

    The lips are the end of the midline whose two outermost channels lie far apart across
    it; of the two, the lower lip moves more and moves with the jaw sensor (the next
    channel from that end): two cues, the confidence from the one that agrees best, low
    when they disagree."""
    xs = {j: med[j][0] for j in mids}
    order = sorted(mids, key=lambda j: -xs[j])
    front = _pair_spread(np.array([med[j] for j in order[:3]]))
    back = _pair_spread(np.array([med[j] for j in order[-3:]]))
    s1 = 1.0 if front >= back else -1.0
    conf = _conf(abs(front - back), 10.0)
    end = order[:3] if s1 > 0 else order[-3:]
    # the lips: far apart across the axis, and in front (a jaw sensor on the gum can lie
    # as low as the lower lip, but behind it)
    pair = max(((p, q) for i, p in enumerate(end) for q in end[i + 1:]),
               key=lambda pq: abs(med[pq[0]][1] - med[pq[1]][1])
               + 0.5 * s1 * (med[pq[0]][0] + med[pq[1]][0]))
    nxt = next(j for j in (order if s1 > 0 else order[::-1]) if j not in pair)
    ranges = {j: _range(series[j][:, 1]) for j in pair}
    by_range = sorted(pair, key=lambda j: ranges[j])  # (upper, lower)
    ratio = ranges[by_range[1]] / max(ranges[by_range[0]], 1e-6)
    corr = {j: _corr(series[j][:, 1], series[nxt][:, 1]) for j in pair}
    by_corr = sorted(pair, key=lambda j: corr[j])  # (upper, lower)
    c_range = _conf(np.log(max(ratio, 1.0)), np.log(2.0))
    c_corr = _conf(abs(corr[pair[0]] - corr[pair[1]]), 0.5)
    if by_range == by_corr:
        upper, lower = by_range
        conf_up = 1.0 - (1.0 - c_range) * (1.0 - c_corr)
    else:
        upper, lower = by_range if c_range >= c_corr else by_corr
        conf_up = abs(c_range - c_corr) * 0.5
    words = (f"the two channels at one end of the midline lie {max(front, back):.0f} mm apart "
             f"across it, at the other end {min(front, back):.0f} mm; the upper lip moves "
             f"{ratio:.1f} times less than the lower, and the lower moves with the next "
             f"channel (vertical correlation {corr[lower]:.2f} against {corr[upper]:.2f})")
    return s1, conf, upper, lower, conf_up, words


def _in_plane(pos, moving, names) -> tuple[dict[str, Guess], float]:
    """The roles of the midline channels ``moving`` (head-corrected ``pos``; steps 3-4) and
    how far apart across the midline the two channels taken for the lips lie (median, mm)."""
    samples = {names[j]: pos[np.isfinite(pos[:, j]).all(-1), j][:_MAX_FRAMES] for j in moving}
    normal, centre, used, dropped = placement.midsagittal_plane(samples)
    guesses: dict[str, Guess] = {}
    mids = [j for j in moving if names[j] in used]
    meds = np.array([np.nanmedian(pos[:, j], axis=0) for j in mids])
    e1 = np.linalg.svd(meds - meds.mean(0) - np.outer((meds - meds.mean(0)) @ normal, normal))[2][0]
    e2 = np.cross(normal, e1)
    series = {j: _series2(pos, j, centre, e1, e2) for j in moving}
    med = {j: np.nanmedian(series[j], axis=0) for j in moving}
    if len(mids) < 4:
        raise placement.PlacementError("fewer than four channels on the midline")
    s1, c_front, upper, lower, c_up, lips_words = _front_and_up(med, series, mids)
    flip = np.array([s1, 1.0 if med[upper][1] > med[lower][1] else -1.0])
    for j in moving:
        series[j] = series[j] * flip
        med[j] = med[j] * flip
    c_lips = min(c_front, c_up)
    guesses[names[upper]] = Guess(names[upper], "UL", c_lips, "front, upper: " + lips_words)
    guesses[names[lower]] = Guess(names[lower], "LL", c_lips, "front, lower: " + lips_words)
    rest = sorted((j for j in mids if j not in (upper, lower)), key=lambda j: -med[j][0])
    # (the jaw sensor: the channel nearest the lips' end, now +x after the flip)
    jaw = rest[0]
    margin = med[jaw][0] - med[rest[1]][0] if len(rest) > 1 else 10.0
    r = _corr(series[jaw][:, 1], series[lower][:, 1])
    c_jaw = min(c_front, _conf(margin, 6.0), _conf(r - 0.2, 0.4))
    guesses[names[jaw]] = Guess(names[jaw], "MNI", c_jaw, (
        f"next from the front behind the lips ({margin:.0f} mm ahead of the next), moving "
        f"with the lower lip (vertical correlation {r:.2f})"))
    molar = None
    rigid = sorted((_rigidity(pos, j, jaw) + (j,) for j in moving
                    if j not in (upper, lower, jaw) and med[j][0] < med[jaw][0] - 20.0),
                   key=lambda t: t[0])
    if rigid and rigid[0][0] < JAW_RIGID_MM and 25.0 <= rigid[0][1] <= 65.0:
        sd, dist, molar = rigid[0]
        runner = rigid[1][0] if len(rigid) > 1 else np.inf
        guesses[names[molar]] = Guess(names[molar], "MNM", min(
            c_jaw, _conf(JAW_RIGID_MM - sd, 0.5), _conf(runner - sd, 1.0)), (
            f"rigid to the jaw sensor (distance {dist:.0f} mm varying by {sd:.1f} mm; the next "
            f"channel's by {runner:.1f} mm)"))
    tongue = [j for j in rest[1:] if j != molar]
    xs = [med[j][0] for j in tongue]
    for i, j in enumerate(tongue):
        gaps = [abs(xs[i] - xs[k]) for k in (i - 1, i + 1) if 0 <= k < len(xs)]
        conf = min(c_front, _conf(min(gaps, default=10.0), 5.0))
        role = f"T{i + 1}" if i < 4 else "extra"
        guesses[names[j]] = Guess(names[j], role, conf, (
            f"tongue (behind the jaw sensor), {i + 1} from the front, {min(gaps, default=0):.0f}"
            " mm from its neighbour along the midline"))
    for name, d in dropped.items():
        j = names.index(name)
        if j != molar:
            guesses[name] = Guess(name, "parasagittal", _conf(abs(d) - placement.MIDLINE_OUTLIER_MM,
                                                              3.0),
                                  f"{abs(d):.0f} mm off the midline (a lip corner or a lateral "
                                  "tongue sensor)")
    return guesses, float(abs(med[upper][1] - med[lower][1]))


def _lips_apart(pos, names, idx, group) -> float:
    """How far apart the lips would lie (median, mm; :func:`_in_plane`) with ``group`` as
    the head references; inf where no midline is found."""
    try:
        return _in_plane(_corrected(pos, list(group)), [j for j in idx if j not in group],
                         names)[1]
    except placement.PlacementError:
        return np.inf


def _session_positions(raws) -> tuple[list[str], np.ndarray]:
    """The channel names and the positions of one file, or of a session's files end to
    end (each thinned to its share of :data:`_MAX_FRAMES`; the files must have the same
    channels)."""
    raws = [raws] if isinstance(raws, RawEma) else list(raws)
    names = list(raws[0].names)
    for raw in raws[1:]:
        if list(raw.names) != names:
            raise ValueError(f"{raw.path}: its channels differ from {raws[0].path}'s")
    share = max(_MAX_FRAMES // len(raws), 100)
    parts = []
    for raw in raws:
        pos = raw.positions
        if pos.shape[0] > share:
            pos = pos[np.linspace(0, pos.shape[0] - 1, share).astype(int)]
        parts.append(pos)
    return names, np.concatenate(parts)


def _across_rivals(found: dict[str, Guess], pos: np.ndarray, names: list[str],
                   moving: list[int], conf: float, rivals: dict[tuple[int, ...], bool]
                   ) -> dict[str, Guess]:
    """The in-plane guesses ``found`` (made with the head group kept) checked against every
    rival head group (:func:`_head_group`): the roles are found again among the same
    channels (less the rival's own members), corrected with the rival group instead. A
    role the same under every rival does not rest on which group is the head: it keeps its
    own confidence, the lowest it has with the kept group and the rivals the evidence does
    not rule out. A role that changes under some rival (or that a rival takes for a
    reference) is capped at the head group's confidence: nothing is surer than the head
    correction it rests on."""
    others = []  # (rival, not ruled out, its guesses)
    for rival, plausible in rivals.items():
        try:
            got = _in_plane(_corrected(pos, list(rival)), [j for j in moving if j not in rival],
                            names)[0]
        except placement.PlacementError:
            got = {}
        others.append((rival, plausible, got))
    out = {}
    for name, g in found.items():
        alt = {rival: got.get(name) for rival, _, got in others}
        if all(a is not None and a.role == g.role for a in alt.values()):
            least = min(((a.confidence, rival) for rival, plausible, _ in others
                         if plausible and (a := alt[rival]).confidence < g.confidence),
                        default=None)
            words = ""
            if alt:
                words = (f"; the same with {'each of the ' if len(alt) > 1 else ''}{len(alt)}"
                         f" other candidate head group{'s' * (len(alt) > 1)}")
            if least is not None and f"{least[0]:.2f}" != f"{g.confidence:.2f}":
                words += (f" (with {'+'.join(names[j] for j in least[1]) or 'no head group'}, "
                          f"not ruled out, only {least[0]:.2f} sure)")
            out[name] = Guess(name, g.role, least[0] if least else g.confidence,
                              g.evidence + words)
        else:
            roles = sorted({"reference" if names.index(name) in rival else
                            "no role" if a is None else a.role
                            for rival, a in alt.items()} - {g.role})
            out[name] = Guess(name, g.role, min(g.confidence, conf), g.evidence + (
                f"; with another candidate head group it would be {' or '.join(roles)}, so "
                "no surer than the head references"))
    return out


def propose_map(raw) -> Proposal:
    """A proposed map for the channels of ``raw`` (a :class:`RawEma`, or a session's files:
    a list of them, read together; module docstring). A session tells more than a file:
    a task where the jaw hardly moves cannot tell the jaw from the skull."""
    names, pos = _session_positions(raw)
    guesses = dict(_unused(pos, names))
    idx = [j for j, n in enumerate(names) if n not in guesses]
    notes = []
    apart = {}  # head group -> how far apart the lips would lie with it

    def mouth(group):  # found once per group
        if group not in apart:
            apart[group] = _lips_apart(pos, names, idx, group)
        return apart[group]

    refs, conf, own, words, rivals = (_head_group(pos, idx, mouth) if pos.shape[2] == 3
                                      else ([], 1.0, {}, "", {}))
    ruled = [g for g, gap in apart.items() if gap > LIPS_APART_MM and list(g) != refs]
    if ruled and apart.get(tuple(refs), 0.0) <= LIPS_APART_MM:
        words += "; not the head, with it the lips would lie too far apart: " + ", ".join(
            f"{'+'.join(names[j] for j in g)} ({apart[g]:.0f} mm)" for g in ruled)
    plausible = ["+".join(names[j] for j in r) or "none (no head correction)"
                 for r, p in rivals.items() if p]
    if plausible:
        words += "; other head groups the data do not rule out: " + ", ".join(plausible)
    for j in refs:
        guesses[names[j]] = Guess(names[j], "reference", own[j], words + (
            "; every rival head group holds this one too" if own[j] > conf else ""))
    if not refs:
        notes.append("no head references found (head-normalised data, or none recorded)")
    moving = [j for j in idx if j not in refs]
    try:
        found = _in_plane(_corrected(pos, refs), moving, names)[0] if pos.shape[2] == 3 else {}
    except placement.PlacementError as exc:
        found = {}
        notes.append(f"roles not proposed: {exc}")
    for name, g in _across_rivals(found, pos, names, moving, conf, rivals).items():
        guesses[name] = g
    for n in names:
        guesses.setdefault(n, Guess(n, "extra", 0.0, "no role found"))
    return Proposal(tuple(guesses[n] for n in names), tuple(notes))


def write_proposed_map(recording, out) -> Proposal:
    """Propose a map for the articulograph file ``recording`` and write it as TOML to
    ``out`` (never over an existing file, nor over an input)."""
    from pathlib import Path

    from .._io import atomic_write
    from .detect import read_ema

    raw = read_ema(Path(recording))
    proposal = propose_map(raw)
    atomic_write(Path(out), proposal.to_toml(str(recording)), overwrite=False)
    return proposal
