"""Which articulograph sensor plays which role: built-in maps and a small TOML file.

Roles: the eight CASSI pellets ``UL LL T1 T2 T3 T4 MNI MNM`` (``MNI`` the lower-incisor
sensor, the one jaw sensor most EMA set-ups have; ``MNM`` a second, rarer jaw sensor); the
head **references** used to remove head movement (upper incisor ``ui``, nose bridge or
nasion, left and right mastoids or ears, any other reference); the **bite plane**
sensors of a bite-plane recording (front, back, left, right). Every other sensor (velum,
lip corners, parasagittal tongue, the references themselves) is kept as an *extra*
sensor of the track, never dropped.

Names are matched without regard to case, spaces, ``_``, ``-`` or ``.`` (``Upper_Lip`` =
``upperlip``). The built-in names (:data:`SYNONYMS`) cover MOCHA-TIMIT (``ui li ul ll tt
tb td v bn``), mngu0 (``T1 T2 T3 jaw upper_lip lower_lip``), SPARC (``TD TB TT LI UL LL``),
the synthetic EMA corpus, and the usual AG501/Wave lab names (``TT TB TD TR UL LL JAW
REF NAS LMA RMA OS MS``). Tongue sensors are ordered front to back by their names (tip,
blade, body, dorsum, rear; or ``t1``..``t4``) and take ``T1`` ... in that order: three
tongue sensors give ``T1 T2 T3`` and leave ``T4`` without a sensor. A tongue role names a
sensor's order, not the model's site: where each sits on the tongue is measured from the
data when the model is fitted (``initialize``, ``SubjectState.tongue_sites``).

A lab's own naming is a TOML file (every table optional; unknown tables or keys are an
error, so a typo is not silently ignored)::

    [channels]          # names for numbered channels (.pos: Ch1..., Wave: S1...)
    1 = "REF"
    3 = "TT"

    [roles]             # CASSI role = sensor name (overrides the built-in names)
    UL = "ULIP"
    MNI = "JAW"

    [references]        # head references (default: the built-in reference names)
    sensors = ["REF", "LMA", "RMA"]
    upper_incisor = "UI"   # a reference on the upper incisor: the toolkit's origin

    [bite_plane]        # sensors of the bite-plane recording (default OS, MS)
    front = "OS"
    back = "MS"
    left = "OL"
    right = "OR"

    [midline]
    sensors = ["V"]     # extra sensors on the midline (used to find the midsagittal plane)

    [file]              # facts about the files the reader cannot know
    scale_mm = 0.01     # the files' numbers times this are millimetres
    anterior = "-x"     # data already in a head frame: the axis toward the face's front
    up = "+y"           # ... and the axis pointing up
    origin = [0.0, -12.5, 3.0]   # the upper incisor's tip, in the file's units and axes
                                 # (before any correction): the toolkit's origin
    occlusal_plane = "declared"  # or [x, y, z]: the occlusal plane's forward direction in
                                 # the file's axes (default: estimated from the jaw)
    jaw_sensor = "gum"  # where the jaw sensor is glued on the lower incisor: "edge",
                        # "gum", "unknown" (default) or its depth below the edge in mm

Without a bite plane or an upper-incisor sensor, the origin and the occlusal plane are
estimated from the speaker's own data (:mod:`cassi_fit.ema.placement`).

A map that names a sensor the file does not have, two sensors for one role, or a role
outside the vocabulary is a :class:`DataFormatError` naming them.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DataFormatError
from ..pellets import PELLET_NAMES

TONGUE = ("T1", "T2", "T3", "T4")
REFERENCE_KINDS = ("upper_incisor", "nasion", "left", "right", "other")
BITE_KINDS = ("front", "back", "left", "right")

# Built-in names (normalised keys) -> role; tongue names -> their order front to back.
_TONGUE_RANK = {
    **dict.fromkeys(("tt", "tonguetip", "tip", "ttip", "t1", "tongue1"), 1.0),
    **dict.fromkeys(("tb", "tongueblade", "blade", "tbl", "t2", "tongue2"), 2.0),
    **dict.fromkeys(("tm", "tonguemid", "tonguemiddle", "tonguebody", "body"), 2.5),
    **dict.fromkeys(("td", "tonguedorsum", "dorsum", "tdo", "t3", "tongue3"), 3.0),
    **dict.fromkeys(("tr", "tongueback", "tonguerear", "tongueroot", "tback", "trear", "t4",
                     "tongue4"), 4.0),
}
SYNONYMS: dict[str, str] = {
    **dict.fromkeys(("ul", "upperlip", "ulip", "uplip", "lipupper"), "UL"),
    **dict.fromkeys(("ll", "lowerlip", "llip", "lolip", "liplower"), "LL"),
    **dict.fromkeys(("li", "lowerincisor", "lowerincisors", "jaw", "mandible", "mand", "mni",
                     "lowerjaw"), "MNI"),
    **dict.fromkeys(("mnm", "lowermolar", "lmol", "jawmolar", "molar", "jaw2"), "MNM"),
    **dict.fromkeys(_TONGUE_RANK, "tongue"),
    **dict.fromkeys(("ui", "upperincisor", "upperincisors", "uinc", "maxilla"),
                    "ref:upper_incisor"),
    **dict.fromkeys(("bn", "nasion", "nas", "nose", "nosebridge", "bridgeofnose"),
                    "ref:nasion"),
    **dict.fromkeys(("lma", "leftmastoid", "mastl", "lmast", "leftear", "lear"), "ref:left"),
    **dict.fromkeys(("rma", "rightmastoid", "mastr", "rmast", "rightear"), "ref:right"),
    **dict.fromkeys(("ref", "reference", "head", "ref1", "ref2", "ref3", "hd"), "ref:other"),
    **dict.fromkeys(("os", "bitefront", "bpfront", "biteplatefront", "occlusalfront"),
                    "bite:front"),
    **dict.fromkeys(("ms", "biteback", "bpback", "biteplateback", "occlusalback"),
                    "bite:back"),
    **dict.fromkeys(("bpl", "biteleft", "bpleft", "osl", "ol"), "bite:left"),
    **dict.fromkeys(("bpr", "biteright", "bpright", "osr", "or"), "bite:right"),
    **dict.fromkeys(("v", "vel", "velum", "softpalate"), "midline"),
}
#: Built-in maps by name: ``"auto"`` uses :data:`SYNONYMS`; the others list a corpus's
#: own names (a file missing one of them is an error naming it).
BUILTIN_MAPS: dict[str, dict[str, str]] = {
    "auto": {},
    "mocha": {"UL": "ul", "LL": "ll", "T1": "tt", "T2": "tb", "T3": "td", "MNI": "li"},
    "mngu0": {"UL": "upper_lip", "LL": "lower_lip", "T1": "T1", "T2": "T2", "T3": "T3",
              "MNI": "jaw"},
    "sparc": {"UL": "UL", "LL": "LL", "T1": "TT", "T2": "TB", "T3": "TD", "MNI": "LI"},
    "synthetic": {"UL": "UL", "LL": "LL", "T1": "TT", "T2": "TB", "T3": "TD", "T4": "TR",
                  "MNI": "LI", "MNM": "LMOL"},
    # IPS Munich EMA (EMU bundles): tb is the tongue's BACK sensor, behind tm (middle);
    # on mo1 it lies near the model's T4 site, found from the data (initialize)
    "ips": {"UL": "ul", "LL": "ll", "T1": "tt", "T2": "tm", "T3": "tb", "MNI": "jw"},
}
#: ``[file]`` facts of built-in maps: the IPS data are head-corrected, posy toward the
#: back of the head, posz up (cassi_fit.ema.emu's docstring says how that was read).
BUILTIN_FILE_FACTS: dict[str, dict[str, str]] = {"ips": {"anterior": "-y", "up": "+z"}}
#: The sensor map "proposed": proposed from each file's data (:mod:`cassi_fit.ema.identify`),
#: what ``--accept-proposed-map`` asks for.
PROPOSED = "proposed"
_TABLES = {"channels", "roles", "references", "bite_plane", "midline", "file"}
_SIGN_AXIS = re.compile(r"^([+-]?)([xyz])$")


_NUMBERED = re.compile(r"^(ch(annel)?|s(ensor)?|coil|c)?[\s_#-]*\d+$", re.IGNORECASE)


def numbered(names) -> bool:
    """True when every channel name is a number (``Ch3``, ``S12``, ``7``)."""
    return bool(names) and all(_NUMBERED.match(str(n).strip()) for n in names)


def sensor_key(name: str) -> str:
    """A sensor name normalised for matching: lower case without spaces, ``_ - .``."""
    return re.sub(r"[\s_.\-]", "", str(name)).lower()


@dataclass(frozen=True)
class SensorMap:
    """A sensor map (module docstring): what a lab's files call each role.

    ``roles``: CASSI role -> sensor name; ``channels``: 1-based channel number -> name;
    ``references``: head reference names (None: the built-in ones); ``upper_incisor``;
    ``bite``: bite-plane kind -> name; ``midline``: extra sensors on the midline;
    ``scale_mm``, ``anterior``, ``up``: the ``[file]`` facts; ``name``: where it came
    from (a built-in name or the TOML file).
    """

    roles: Mapping[str, str] = field(default_factory=dict)
    channels: Mapping[int, str] = field(default_factory=dict)
    references: tuple[str, ...] | None = None
    upper_incisor: str | None = None
    bite: Mapping[str, str] = field(default_factory=dict)
    midline: tuple[str, ...] = ()
    scale_mm: float | None = None
    anterior: str | None = None
    up: str | None = None
    name: str = "auto"
    origin: tuple[float, ...] | None = None
    occlusal_plane: str | tuple[float, ...] | None = None
    jaw_sensor: str | float = "unknown"

    def __post_init__(self):
        where = self.name if self.name.endswith(".toml") else None
        for role in self.roles:
            if role not in PELLET_NAMES:
                raise DataFormatError(where, None, f"unknown role {role!r} (roles: "
                                      f"{', '.join(PELLET_NAMES)})")
        named = [sensor_key(s) for s in self.roles.values()]
        dup = sorted({s for s in named if named.count(s) > 1})
        if dup:
            raise DataFormatError(where, None, f"sensor {dup[0]!r} given two roles")
        for kind in self.bite:
            if kind not in BITE_KINDS:
                raise DataFormatError(where, None, f"unknown bite_plane key {kind!r} "
                                      f"({', '.join(BITE_KINDS)})")
        for key in ("anterior", "up"):
            value = getattr(self, key)
            if value is not None and not _SIGN_AXIS.match(value.strip().lower()):
                raise DataFormatError(where, None, f"[file] {key} = {value!r}: expected an "
                                      "axis such as '+x', '-x', 'y', '+z'")
        if (self.anterior is None) != (self.up is None):
            raise DataFormatError(where, None, "[file] needs both anterior and up (or neither)")
        if self.scale_mm is not None and not (self.scale_mm > 0 and math.isfinite(
                self.scale_mm)):
            raise DataFormatError(where, None, f"[file] scale_mm {self.scale_mm!r} must be a "
                                  "finite number > 0")
        _check_frame_keys(where, self)


def _numbers(value, n=(2, 3)) -> bool:
    return (isinstance(value, list | tuple) and len(value) in n and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in value))


def _check_frame_keys(where, smap) -> None:
    """``[file] origin``, ``occlusal_plane`` and ``jaw_sensor`` (module docstring)."""
    from .placement import JAW_SENSOR_KINDS

    if smap.origin is not None and not _numbers(smap.origin):
        raise DataFormatError(where, None, f"[file] origin = {smap.origin!r}: expected [x, y, z]"
                              " (or [x, y]) numbers in the file's units and axes")
    plane = smap.occlusal_plane
    if plane is not None and plane != "declared" and not (
            _numbers(plane) and any(v != 0 for v in plane)):
        raise DataFormatError(where, None, f"[file] occlusal_plane = {plane!r}: expected "
                              "\"declared\" or a direction [x, y, z] in the file's axes")
    if plane == "declared" and smap.anterior is None:
        raise DataFormatError(where, None, '[file] occlusal_plane = "declared" needs the axes '
                              "(anterior, up)")
    jaw = smap.jaw_sensor
    ok = jaw in JAW_SENSOR_KINDS if isinstance(jaw, str) else (
        isinstance(jaw, int | float) and not isinstance(jaw, bool) and 0 <= jaw <= 25)
    if not ok:
        raise DataFormatError(where, None, f"[file] jaw_sensor = {jaw!r}: expected "
                              f"{', '.join(map(repr, JAW_SENSOR_KINDS))} or a depth in mm (0-25)")


def builtin_map(name: str) -> SensorMap:
    """The built-in map ``name`` (:data:`BUILTIN_MAPS`)."""
    key = str(name).strip().lower()
    if key not in BUILTIN_MAPS:
        raise DataFormatError(None, None, f"unknown sensor map {name!r} (built in: "
                              f"{', '.join(BUILTIN_MAPS)}; or a .toml file)")
    return SensorMap(roles=BUILTIN_MAPS[key], name=key, **BUILTIN_FILE_FACTS.get(key, {}))


def _strings(where, table: str, key: str, value) -> tuple[str, ...]:
    if isinstance(value, str):
        return (value,)
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return tuple(value)
    raise DataFormatError(where, None, f"[{table}] {key} must be a name or a list of names")


def _check_keys(where, table: str, given: Mapping, allowed: Sequence[str]) -> None:
    unknown = [k for k in given if k not in allowed]
    if unknown:
        raise DataFormatError(where, None, f"[{table}] unknown key {unknown[0]!r} (expected "
                              f"{', '.join(allowed)})")


def read_sensor_map(path: str | os.PathLike) -> SensorMap:
    """Read a TOML sensor map (module docstring); a :class:`DataFormatError` naming the
    file for a syntax error, an unknown table or key, a value of the wrong kind."""
    import tomllib

    from ._raw import read_bytes  # regular files only: a FIFO would block for ever

    path, raw = read_bytes(path, "sensor map")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, None, f"not a TOML sensor map ({exc})") from None
    _check_keys(path, "top level", data, sorted(_TABLES))
    for table, value in data.items():
        if not isinstance(value, dict):
            raise DataFormatError(path, None, f"{table} must be a [table]")
    channels = {}
    for key, value in data.get("channels", {}).items():
        if not key.isdigit() or int(key) < 1 or not isinstance(value, str):
            raise DataFormatError(path, None, f"[channels] {key} = {value!r}: expected a "
                                  "channel number (1, 2, ...) = a name")
        channels[int(key)] = value
    roles = {}
    for key, value in data.get("roles", {}).items():
        if not isinstance(value, str):
            raise DataFormatError(path, None, f"[roles] {key} must be a sensor name")
        roles[key.upper()] = value
    refs = data.get("references", {})
    _check_keys(path, "references", refs, ("sensors", "upper_incisor"))
    bite = data.get("bite_plane", {})
    _check_keys(path, "bite_plane", bite, BITE_KINDS)
    midline = data.get("midline", {})
    _check_keys(path, "midline", midline, ("sensors",))
    facts = data.get("file", {})
    _check_keys(path, "file", facts, ("scale_mm", "anterior", "up", "origin",
                                       "occlusal_plane", "jaw_sensor"))
    scale = facts.get("scale_mm")
    if scale is not None and (isinstance(scale, bool) or not isinstance(scale, int | float)):
        raise DataFormatError(path, None, "[file] scale_mm must be a number")
    for table, key, value in (("file", "anterior", facts.get("anterior")),
                              ("file", "up", facts.get("up")),
                              ("references", "upper_incisor", refs.get("upper_incisor"))):
        if value is not None and not isinstance(value, str):
            raise DataFormatError(path, None, f"[{table}] {key} must be text, got {value!r}")
    return SensorMap(
        roles=roles,
        channels=channels,
        references=(_strings(path, "references", "sensors", refs["sensors"])
                    if "sensors" in refs else None),
        upper_incisor=refs.get("upper_incisor"),
        bite={k: _strings(path, "bite_plane", k, v)[0] for k, v in bite.items()},
        midline=_strings(path, "midline", "sensors", midline.get("sensors", [])),
        scale_mm=None if scale is None else float(scale),
        anterior=facts.get("anterior"),
        up=facts.get("up"),
        name=str(path),
        origin=_listed(facts.get("origin")),
        occlusal_plane=_listed(facts.get("occlusal_plane")),
        jaw_sensor=facts.get("jaw_sensor", "unknown"),
    )


def _listed(value):
    return tuple(value) if isinstance(value, list) else value


def sensor_map(value: SensorMap | str | os.PathLike | None) -> SensorMap:
    """A :class:`SensorMap` from a map, a built-in name, a ``.toml`` path, None
    (``"auto"``) or ``"proposed"`` (:data:`PROPOSED`: proposed from each file's data when
    it is read)."""
    if value is None:
        return builtin_map("auto")
    if isinstance(value, SensorMap):
        return value
    if str(value) == PROPOSED:
        return SensorMap(name=PROPOSED)
    text = os.fspath(value)
    if text.lower().endswith(".toml") or Path(text).is_file():
        return read_sensor_map(text)
    return builtin_map(text)


@dataclass(frozen=True)
class Assignment:
    """Sensors of one file resolved against a map: every name is the file's (renamed by
    ``[channels]``).

    ``names``: all sensors in file order; ``roles``: CASSI role -> sensor; ``references``:
    kind (:data:`REFERENCE_KINDS`) -> sensor names; ``bite``: kind -> sensor; ``extras``:
    the sensors with no CASSI role, file order; ``midline``: the sensors believed to lie
    on the midline (CASSI roles, upper incisor, nasion, bite front/back, midline extras);
    ``notes``: what the resolution decided.
    """

    names: tuple[str, ...]
    roles: Mapping[str, str]
    references: Mapping[str, tuple[str, ...]]
    bite: Mapping[str, str]
    extras: tuple[str, ...]
    midline: frozenset[str]
    notes: tuple[str, ...] = ()

    @property
    def reference_names(self) -> tuple[str, ...]:
        """Every head reference sensor, in file order."""
        refs = {s for names in self.references.values() for s in names}
        return tuple(s for s in self.names if s in refs)

    @property
    def upper_incisor(self) -> str | None:
        found = self.references.get("upper_incisor", ())
        return found[0] if found else None


def _find(where, names: Sequence[str], wanted: str, what: str) -> str:
    key = sensor_key(wanted)
    for name in names:
        if sensor_key(name) == key:
            return name
    raise DataFormatError(where, None, f"{what} {wanted!r} is not in the file (its sensors: "
                          f"{', '.join(names)})")


def rename_channels(names: Sequence[str], channels: Mapping[int, str], where=None) -> tuple[
        str, ...]:
    """``names`` with ``[channels]`` applied (1-based positions)."""
    out = list(names)
    for number, new in channels.items():
        if number > len(out):
            raise DataFormatError(where, None, f"[channels] {number}: the file has only "
                                  f"{len(out)} channels")
        out[number - 1] = new
    if len({sensor_key(s) for s in out}) != len(out):
        raise DataFormatError(where, None, f"after [channels], two sensors share a name: "
                              f"{', '.join(out)}")
    return tuple(out)


def resolve(names: Sequence[str], smap: SensorMap, where: str | os.PathLike | None = None,
            *, bite_plane: bool = False) -> Assignment:
    """Resolve a file's sensor ``names`` against ``smap`` (module docstring): explicit
    roles first, then the built-in names for the rest; tongue sensors front to back.
    ``bite_plane``: the file is a bite-plane recording (its bite sensors must exist, and
    it needs no CASSI role)."""
    names = rename_channels(names, smap.channels, where)
    roles: dict[str, str] = {r: _find(where, names, s, f"role {r}: sensor")
                             for r, s in smap.roles.items()
                             if not bite_plane or sensor_key(s) in map(sensor_key, names)}
    taken = set(roles.values())
    refs: dict[str, list[str]] = {k: [] for k in REFERENCE_KINDS}
    bite: dict[str, str] = {}
    keys = {sensor_key(n) for n in names}
    for kind, wanted in smap.bite.items():  # bite sensors are only in bite recordings
        if bite_plane or sensor_key(wanted) in keys:
            bite[kind] = _find(where, names, wanted, f"bite_plane {kind}: sensor")
    taken |= set(bite.values())
    midline = {_find(where, names, s, "midline sensor") for s in smap.midline}
    if smap.upper_incisor is not None:
        refs["upper_incisor"].append(_find(where, names, smap.upper_incisor,
                                           "references: upper_incisor"))
    explicit_refs = None
    if smap.references is not None:
        explicit_refs = [_find(where, names, s, "reference") for s in smap.references]
    tongue, seen_role = [], {}
    for name in names:
        if name in taken:
            continue
        key = sensor_key(name)
        kind = SYNONYMS.get(key)
        if kind is None:
            continue
        if kind == "tongue":
            tongue.append((_TONGUE_RANK[key], name))
        elif kind in PELLET_NAMES and kind not in roles:
            if kind in seen_role:
                raise DataFormatError(where, None, f"sensors {seen_role[kind]!r} and {name!r} "
                                      f"both look like {kind}: name one in a sensor map")
            seen_role[kind] = name
        elif kind.startswith("ref:") and explicit_refs is None:
            if not (kind == "ref:upper_incisor" and refs["upper_incisor"]):
                refs[kind[4:]].append(name)
        elif kind.startswith("bite:") and kind[5:] not in bite:
            bite[kind[5:]] = name
        elif kind == "midline":
            midline.add(name)
    roles.update(seen_role)
    notes = []
    free = [r for r in TONGUE if r not in roles]
    tongue.sort()
    if len(tongue) > len(free):
        notes.append(f"tongue sensor(s) {', '.join(n for _, n in tongue[len(free):])} beyond "
                     f"{', '.join(free)} kept as extra sensors")
    for role, (_, name) in zip(free, tongue, strict=False):
        roles[role] = name
    if explicit_refs is not None:
        for name in explicit_refs:
            kind = SYNONYMS.get(sensor_key(name), "ref:other")
            kind = kind[4:] if kind.startswith("ref:") else "other"
            if name not in refs["upper_incisor"]:
                refs[kind].append(name)
    if not roles and not bite_plane:
        hint = ("; `cassi info --write-sensor-map FILE` proposes one from the data, "
                "--accept-proposed-map uses it" if numbered(names) else "")
        raise DataFormatError(where, None, f"no sensor maps to a CASSI role (UL, LL, T1-T4, "
                              f"MNI, MNM): the file's sensors are {', '.join(names)}; give a "
                              f"sensor map (docs/EMA.md){hint}")
    in_roles = set(roles.values())
    ordered_roles = {r: roles[r] for r in PELLET_NAMES if r in roles}
    extras = tuple(s for s in names if s not in in_roles)
    midline |= in_roles | set(refs["upper_incisor"]) | set(refs["nasion"])
    midline |= {bite[k] for k in ("front", "back") if k in bite}
    return Assignment(names=names, roles=ordered_roles,
                      references={k: tuple(v) for k, v in refs.items() if v},
                      bite=dict(bite), extras=extras, midline=frozenset(midline),
                      notes=tuple(notes))
