"""EMU-SDMS databases (emuDB): articulograph tracks, the sound and the annotation of bundles.

An emuDB on disk (EMU-SDMS's documented layout) is a folder holding
``<name>_DBconfig.json`` and session folders ``<session>_ses/``, each holding bundle
folders ``<bundle>_bndl/`` with the sound (``<bundle>.wav``, the DBconfig's
``mediafileExtension``), the annotation ``<bundle>_annot.json`` and one SSFF track file
per track (``<bundle>.<fileExtension>``, :mod:`cassi_fit.ema.ssff`). The EMU-webApp serves
one bundle as a JSON file (``<bundle>_bndl.json``: ``mediaFile`` and ``ssffFiles`` as
base64, ``annotation``); both are read here into one :class:`~cassi_fit.ema._raw.RawEma`
(``format = "emu"``) with the sound and the label tiers inside it. A session is a
subject, a bundle a task.

**Tracks to sensors.** The DBconfig's ``ssffTrackDefinitions`` say which SSFF files are
tracks (their ``fileExtension``); they name some columns only (the IPS Munich database
names ``posy`` and ``posz``): every position column of each file is used, ``posx``
included. A column ``<sensor>_<axis>`` (``tt_posx``, ``UL_x``) is one coordinate of a
sensor; a column of 2 or 3 values named ``<sensor>_pos`` is a whole position. Other
columns (orientations, formants) are not sensors. A record whose every column is exactly
0 is untracked (EMU exports pad the end of each track with such records: never a sensor
at the origin). Tracks must share their rate and start time; a shorter one is untracked
after its end. A definition naming a column its file lacks is an error naming both.

**Annotation to labels.** Each level becomes a label tier of its name: ``SEGMENT``
items are intervals (``sampleStart`` to ``sampleStart + sampleDur``, at the annotation's
``sampleRate``), ``EVENT`` items points, ``ITEM`` items take the span of the timed items
they dominate through the ``links``. Items with an empty label are not segments.

**Units and axes.** EMU files state neither: millimetres are assumed. The IPS Munich EMA
databases (``tt tm tb ul ll jw``: tongue tip, middle and back, lips, jaw) have the
built-in sensor map ``ips`` (:func:`sensor_map_for`): ``posy`` grows toward the back of the
head, ``posz`` up, ``posx`` lateral, the origin near the upper incisors (read from the IPS
demo bundle dfgspp_mo1_prosody_0024: the upper lip at posy -9.6 mm, the tongue back at
+50 mm; the lower lip 17 mm below the upper).
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import re
from pathlib import Path

import numpy as np

from ..errors import DataFormatError, MissingDataError
from ._raw import POSITION_AXES, RawEma, assemble_channels, read_bytes, split_channel
from .ssff import MAGIC as SSFF_MAGIC
from .ssff import SsffTrack, parse_ssff

DBCONFIG_SUFFIX = "_DBconfig.json"
SESSION_SUFFIX = "_ses"
BUNDLE_SUFFIX = "_bndl"
ANNOT_SUFFIX = "_annot.json"
#: The IPS Munich EMA set (sensor names of its columns) and its sensor map.
IPS_SENSORS = frozenset({"tt", "tm", "tb", "ul", "ll", "jw"})
_POS_COLUMN = re.compile(r"^(?P<sensor>.*?)[_.\-]?(pos|position|xyz)$", re.IGNORECASE)


# ------------------------------------------------------------------ finding things
def is_bundle_folder(path: Path) -> bool:
    """Whether ``path`` is a folder named ``<bundle>_bndl``."""
    return path.name.endswith(BUNDLE_SUFFIX) and path.is_dir()


def is_bundle_json(head: bytes, path: Path) -> bool:
    """Whether a file looks like a bundle JSON as the EMU-webApp serves it."""
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    return text.startswith(b"{") and (b'"ssffFiles"' in head or b'"mediaFile"' in head or (
        path.name.endswith(BUNDLE_SUFFIX + ".json") and b'"annotation"' in head))


def find_dbconfig(folder: Path) -> Path | None:
    """The ``*_DBconfig.json`` in ``folder`` (regular files only), or None; two are an
    error naming them."""
    try:
        found = sorted(p for p in folder.iterdir()
                       if p.name.endswith(DBCONFIG_SUFFIX) and p.is_file())
    except OSError:
        return None
    if len(found) > 1:
        raise DataFormatError(folder, None, f"{len(found)} EMU database configurations "
                              f"({', '.join(p.name for p in found)}): one per database")
    return found[0] if found else None


def database_bundles(root: Path) -> list[tuple[str, str, Path]]:
    """``(session, bundle, bundle folder)`` of every bundle of the emuDB at ``root`` (a
    folder with a ``*_DBconfig.json``), by folder listings only."""
    out = []
    for session in sorted(p for p in root.iterdir()
                          if p.name.endswith(SESSION_SUFFIX) and p.is_dir()):
        for bundle in sorted(p for p in session.iterdir() if is_bundle_folder(p)):
            out.append((session.name[: -len(SESSION_SUFFIX)],
                        bundle.name[: -len(BUNDLE_SUFFIX)], bundle))
    return out


def bundle_name(path: Path) -> str:
    """``<bundle>`` of a ``<bundle>_bndl`` folder or ``<bundle>_bndl.json`` file."""
    stem = path.name[:-5] if path.name.lower().endswith(".json") else path.name
    return stem[: -len(BUNDLE_SUFFIX)] if stem.endswith(BUNDLE_SUFFIX) else stem


def session_of(path: Path) -> str | None:
    """The session of a bundle folder inside ``<session>_ses``, else None."""
    parent = path.parent.name
    return parent[: -len(SESSION_SUFFIX)] if parent.endswith(SESSION_SUFFIX) else None


def recording_names(path: Path, folder: Path) -> tuple[str, str]:
    """``(SUBJECT, task)`` of a bundle: its session (else ``folder``'s name), its name."""
    return (session_of(path) or folder.name).upper(), bundle_name(path).lower()


# ----------------------------------------------------------------------- config
def read_dbconfig(path: Path) -> dict:
    """The DBconfig's JSON; an error naming the file if it is not an EMU configuration."""
    config = _json(path, read_bytes(path, "EMU database configuration")[1])
    defs = config.get("ssffTrackDefinitions", [])
    if not isinstance(config, dict) or not isinstance(defs, list) or not all(
            isinstance(d, dict) and isinstance(d.get("fileExtension"), str) for d in defs):
        raise DataFormatError(path, None, "not an EMU database configuration (its "
                              "ssffTrackDefinitions must list tracks with a fileExtension)")
    return config


def _json(where, raw: bytes):
    try:
        return json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        line = getattr(exc, "lineno", None)
        raise DataFormatError(where, line, f"not valid JSON ({str(exc).split(':')[0]})") from None


def _config_for(path: Path) -> tuple[dict | None, Path | None]:
    """The DBconfig of a bundle: two folders up (a database on disk), else beside the
    bundle's folder or JSON file."""
    for folder in (path.parent.parent, path.parent):
        found = find_dbconfig(folder)
        if found is not None:
            return read_dbconfig(found), found
    return None, None


# ----------------------------------------------------------------------- tracks
def _position_columns(track: SsffTrack) -> dict[str, np.ndarray]:
    """``<sensor>_<axis>`` -> ``(n,)`` for every position column of a track."""
    out = {}
    for name, values in track.columns.items():
        if values.shape[1] == 1:
            sensor, axis = split_channel(name)
            if axis in POSITION_AXES:
                out[name] = values[:, 0]
        elif values.shape[1] in (2, 3) and (m := _POS_COLUMN.match(name)) and m["sensor"]:
            for c in range(values.shape[1]):
                out[f"{m['sensor']}_{'xyz'[c]}"] = values[:, c]
    return out


def _raw_from_tracks(where, tracks: list[tuple[str, SsffTrack]], defs: list[dict],
                     notes: list[str]) -> tuple[np.ndarray, list[str], np.ndarray, float]:
    """``(times, channel names, values (n, c), rate)`` of the sensor tracks."""
    by_ext = {ext: track for ext, track in tracks}
    for d in defs:
        track = by_ext.get(d["fileExtension"])
        column = d.get("columnName")
        if track is not None and column and column not in track.columns:
            raise DataFormatError(track.path, None, f"the DBconfig's track {d.get('name')!r} "
                                  f"names column {column!r}, which this file lacks (it has "
                                  f"{', '.join(track.columns)})")
    sensors, zeros = [], {}
    for ext, track in tracks:
        columns = _position_columns(track)
        if not columns:
            notes.append(f"track {ext} ({', '.join(track.columns)}): not a sensor")
            continue
        zero = np.all([(v == 0).all(axis=1) for v in track.columns.values()], axis=0)
        if zero.any():
            tail = track.n_records - int(np.flatnonzero(~zero)[-1]) - 1 if (~zero).any() \
                else track.n_records
            what = f"the last {tail}" if tail == zero.sum() else f"{int(zero.sum())}"
            zeros.setdefault(what, []).append(ext)
        sensors.append((ext, track, columns, zero))
    for what, exts in zeros.items():
        notes.append(f"{what} record(s) of track(s) {', '.join(exts)} are all exactly 0 (EMU "
                     "padding): untracked")
    if not sensors:
        raise DataFormatError(where, None, "no SSFF track holds sensor positions (columns "
                              "such as tt_posx, tt_posy, tt_posz)")
    first = sensors[0][1]
    for ext, track, _, _ in sensors[1:]:
        if track.rate_hz != first.rate_hz or track.start_s != first.start_s:
            raise DataFormatError(track.path, None, f"track {ext}: {track.rate_hz:g} Hz from "
                                  f"{track.start_s:g} s, but {sensors[0][0]} has "
                                  f"{first.rate_hz:g} Hz from {first.start_s:g} s (tracks "
                                  "must share both)")
    n = max(track.n_records for _, track, _, _ in sensors)
    names: list[str] = []
    values = []
    for ext, track, columns, zero in sensors:
        if track.n_records < n:
            notes.append(f"track {ext}: {track.n_records} records, others {n}: untracked "
                         "after its end")
        for name, column in columns.items():
            full = np.full(n, np.nan)
            full[: track.n_records] = np.where(zero, np.nan, column)
            names.append(name)
            values.append(full)
    times = first.start_s + np.arange(n) / first.rate_hz
    return times, names, np.stack(values, axis=1), first.rate_hz


def _bundle_raw(where: Path, tracks, defs, sound, annotation, annot_where) -> RawEma:
    notes: list[str] = []
    times, channels, values, rate = _raw_from_tracks(where, tracks, defs, notes)
    names, positions, orientation, more = assemble_channels(where, channels, values)
    labels = annotation_tiers(annot_where, annotation, notes) if annotation else ()
    if sound is not None:
        notes.append(f"sound: {sound.source}")
    return RawEma(format="emu", times=times, names=names, positions=positions,
                  rate_hz=rate, units="mm (EMU SSFF: units not stated; mm assumed)",
                  axes="not stated by the files (EMU tracks)", frame=None, path=where,
                  orientation=orientation, notes=tuple(notes + more), sound=sound,
                  labels=labels)


# -------------------------------------------------------------------- annotation
def _label(item: dict, level: str) -> str:
    labels = item.get("labels") or []
    for lab in labels:
        if isinstance(lab, dict) and lab.get("name") == level:
            return str(lab.get("value", ""))
    return str(labels[0].get("value", "")) if labels and isinstance(labels[0], dict) else ""


def annotation_tiers(where, annotation: dict, notes: list[str]) -> tuple:
    """The label tiers of an EMU annotation (module docstring)."""
    from ..labels import Labels

    try:
        rate = float(annotation["sampleRate"])
        levels = list(annotation.get("levels", []))
        links = [(int(k["fromID"]), int(k["toID"])) for k in annotation.get("links", [])]
    except (KeyError, TypeError, ValueError):
        raise DataFormatError(where, None, "not an EMU annotation (sampleRate, levels, "
                              "links)") from None
    if not rate > 0:
        raise DataFormatError(where, None, f"annotation sampleRate {rate!r} is not a rate")
    span: dict[int, tuple[float, float]] = {}
    for level in levels:
        for item in level.get("items", []):
            try:
                if level.get("type") == "SEGMENT":
                    s = float(item["sampleStart"])
                    span[int(item["id"])] = (s / rate, (s + float(item["sampleDur"])) / rate)
                elif level.get("type") == "EVENT":
                    p = float(item["samplePoint"]) / rate
                    span[int(item["id"])] = (p, p)
            except (KeyError, TypeError, ValueError):
                raise DataFormatError(where, None, f"level {level.get('name')!r}: item "
                                      f"{item.get('id')!r} has no sample times") from None
    children: dict[int, list[int]] = {}
    for a, b in links:
        children.setdefault(a, []).append(b)

    def timed(i: int, seen: frozenset = frozenset()) -> tuple[float, float] | None:
        if i in span:
            return span[i]
        found = [t for c in children.get(i, []) if c not in seen
                 if (t := timed(c, seen | {i})) is not None]
        return (min(t[0] for t in found), max(t[1] for t in found)) if found else None

    tiers = []
    for level in levels:
        name = str(level.get("name", ""))
        rows = []
        for item in level.get("items", []):
            t = timed(int(item.get("id", -1)))
            label = _label(item, name).strip()
            if t is not None and label:
                rows.append((t[0], t[1], label))
        if not rows:
            continue
        rows.sort(key=lambda r: r[0])
        try:
            tiers.append(Labels([r[0] for r in rows], [r[1] for r in rows],
                                [r[2] for r in rows], name, where))
        except DataFormatError as exc:
            raise DataFormatError(where, None, f"level {name!r}: {exc.reason}") from None
        notes.append(f"level {name} ({level.get('type')}): {len(rows)} labels")
    return tuple(tiers)


# ----------------------------------------------------------------------- readers
def _defs_exts(config: dict | None) -> set[str] | None:
    if config is None:
        return None
    return {d["fileExtension"] for d in config.get("ssffTrackDefinitions", [])}


def read_bundle_folder(path: Path) -> RawEma:
    """A bundle folder ``<bundle>_bndl`` of an emuDB (module docstring)."""
    from ..sound import Sound

    path = Path(path)
    name = bundle_name(path)
    config, _ = _config_for(path)
    exts = _defs_exts(config)
    media_ext = (config or {}).get("mediafileExtension", "wav")
    files = {p.name: p for p in sorted(path.iterdir()) if p.is_file()}
    tracks = []
    for fname, fpath in files.items():
        if not fname.startswith(name + "."):
            continue
        ext = fname[len(name) + 1:]
        if ext == media_ext or (exts is not None and ext not in exts):
            continue
        raw = read_bytes(fpath, "SSFF file")[1]
        if exts is not None or raw.startswith(SSFF_MAGIC.encode()):
            tracks.append((ext, parse_ssff(raw, fpath)))
    if exts is not None:
        missing = sorted(exts - {e for e, _ in tracks})
        if missing and not tracks:
            raise MissingDataError(f"{path}: no track files ({', '.join(f'{name}.{e}' for e in missing)})")
    if not tracks:
        raise DataFormatError(path, None, "an EMU bundle folder without SSFF track files")
    media = files.get(f"{name}.{media_ext}")
    sound = None if media is None else Sound.from_file(media, "EMU media")
    annot_path = files.get(name + ANNOT_SUFFIX)
    annotation = None
    if annot_path is not None:
        annotation = _json(annot_path, read_bytes(annot_path, "annotation")[1])
    return _bundle_raw(path, tracks, (config or {}).get("ssffTrackDefinitions", []), sound,
                       annotation, annot_path)


def read_bundle_json(path: Path) -> RawEma:
    """A bundle as the EMU-webApp serves it: one JSON file (module docstring)."""
    from ..sound import Sound

    path, raw = read_bytes(path, "EMU bundle")
    bundle = _json(path, raw)
    if not isinstance(bundle, dict) or not isinstance(bundle.get("ssffFiles"), list):
        raise DataFormatError(path, None, "not an EMU bundle (no ssffFiles list)")
    config, _ = _config_for(path)
    exts = _defs_exts(config)
    tracks = []
    for k, entry in enumerate(bundle["ssffFiles"]):
        ext = entry.get("fileExtension") if isinstance(entry, dict) else None
        where = f"{path}: ssffFiles[{k}] ({ext})"
        if not isinstance(ext, str) or (exts is not None and ext not in exts):
            continue
        tracks.append((ext, parse_ssff(_base64(where, entry), where)))
    sound = None
    media = bundle.get("mediaFile")
    if isinstance(media, dict) and media.get("data"):
        where = f"{path}: mediaFile"
        sound = Sound(where, "EMU media", data=_base64(where, media))
    annotation = bundle.get("annotation")
    return _bundle_raw(path, tracks, (config or {}).get("ssffTrackDefinitions", []), sound,
                       annotation if isinstance(annotation, dict) else None, path)


def _base64(where: str, entry: dict) -> bytes:
    if str(entry.get("encoding", "BASE64")).upper() != "BASE64":
        raise DataFormatError(where, None, f"encoding {entry.get('encoding')!r}: only BASE64 "
                              "is read")
    try:
        return base64.b64decode(entry.get("data", ""), validate=True)
    except (binascii.Error, ValueError, TypeError):
        raise DataFormatError(where, None, "data is not valid base64") from None


def read_emu(path: str | os.PathLike) -> RawEma:
    """A bundle folder or a bundle JSON file (module docstring)."""
    path = Path(path)
    return read_bundle_folder(path) if path.is_dir() else read_bundle_json(path)


def sensor_map_for(raw: RawEma):
    """The built-in map for an EMU recording whose sensors are the IPS Munich set
    (``"ips"``), else None."""
    from .sensor_map import builtin_map

    if raw.format == "emu" and {n.lower() for n in raw.names} == IPS_SENSORS:
        return builtin_map("ips")
    return None


# ----------------------------------------------------------------------- writers
#: Records an EMU export pads the end of each track with (all exactly 0): 0.2 s at 200 Hz.
PAD_RECORDS = 40


def track_extension(sensor: str) -> str:
    """The SSFF file extension :func:`write_bundle` gives a sensor's track."""
    return f"trk_{sensor.lower()}"


def _annotation(name: str, session: str, tiers, rate: float) -> dict:
    """An EMU annotation: one SEGMENT level per tier and, for a tier named ``Segment``, an
    ITEM level ``Word`` above it (one item linked to every segment)."""
    levels, links, next_id = [], [], 0
    for tier in tiers:
        items = []
        for seg in tier.segments():
            start = int(round(seg.start * rate))
            items.append({"id": next_id, "sampleStart": start,
                          "sampleDur": max(int(round(seg.end * rate)) - start, 0),
                          "labels": [{"name": tier.tier, "value": seg.label}]})
            next_id += 1
        levels.append({"name": tier.tier, "type": "SEGMENT", "items": items})
        if tier.tier == "Segment" and items:
            word = {"id": next_id, "labels": [{"name": "Word",
                                               "value": "_".join(tier.labels)}]}
            levels.insert(0, {"name": "Word", "type": "ITEM", "items": [word]})
            links += [{"fromID": next_id, "toID": it["id"]} for it in items]
            next_id += 1
    return {"name": name, "annotates": f"{session}{SESSION_SUFFIX}/{name}{BUNDLE_SUFFIX}/"
            f"{name}.wav", "sampleRate": rate, "levels": levels, "links": links}


def write_bundle(folder: str | os.PathLike, session: str, name: str, raw: RawEma, *,
                 wav: str | os.PathLike | None = None, tiers=(), annotation_rate: float = 16000.0,
                 pad_records: int = PAD_RECORDS, overwrite: bool = False) -> Path:
    """Write ``raw`` as the bundle ``folder/<name>_bndl/`` of an emuDB session folder: one
    SSFF track per sensor (:func:`track_extension`; columns ``<sensor>_posx/posy/posz``
    and three orientation columns, FLOAT), the last ``pad_records`` records replaced by
    exact zeros as EMU exports pad them, the ``.wav`` copied in, the ``tiers`` (``Labels``)
    as the annotation's levels. Returns the bundle folder."""
    from .._io import atomic_write
    from .ssff import ssff_bytes

    bundle = Path(folder) / f"{name}{BUNDLE_SUFFIX}"
    n = raw.n_frames
    pad = np.zeros(n, bool)
    pad[max(n - pad_records, 0):] = True
    for j, sensor in enumerate(raw.names):
        pos = np.where(pad[:, None], 0.0, raw.positions[:, j, :])
        columns = {f"{sensor}_pos{'xyz'[c]}": pos[:, c] for c in range(raw.dims)}
        columns.update({f"{sensor}_ori{a}": np.where(pad, 0.0, v) for a, v in
                        zip("xyz", (1.0, 0.0, 0.0), strict=True)})
        atomic_write(bundle / f"{name}.{track_extension(sensor)}",
                     ssff_bytes(columns, raw.rate_hz, start_s=float(raw.times[0])),
                     overwrite=overwrite, data_file=True)
    if wav is not None:
        atomic_write(bundle / f"{name}.wav", Path(wav).read_bytes(), overwrite=overwrite,
                     data_file=True)
    annotation = _annotation(name, session, tiers, annotation_rate)
    atomic_write(bundle / f"{name}{ANNOT_SUFFIX}", json.dumps(annotation, indent=1) + "\n",
                 overwrite=overwrite)
    return bundle


def write_dbconfig(root: str | os.PathLike, name: str, sensors, *, dims: int = 3,
                   levels=("Word", "Segment"), overwrite: bool = False) -> Path:
    """Write ``root/<name>_DBconfig.json`` naming, as the IPS database does, only the
    ``posy`` and ``posz`` columns of each sensor's track (readers must use ``posx`` too)."""
    from .._io import atomic_write

    defs = [{"name": f"{s}_pos{a}", "columnName": f"{s}_pos{a}",
             "fileExtension": track_extension(s)} for s in sensors for a in "yz"[: dims - 1]]
    kinds = {"Word": "ITEM"}
    config = {"name": name, "UUID": "00000000-0000-0000-0000-000000000000",
              "mediafileExtension": "wav", "ssffTrackDefinitions": defs,
              "levelDefinitions": [{"name": lv, "type": kinds.get(lv, "SEGMENT"),
                                    "attributeDefinitions": [{"name": lv, "type": "STRING"}]}
                                   for lv in levels],
              "linkDefinitions": [{"type": "ONE_TO_MANY", "superlevelName": "Word",
                                   "sublevelName": "Segment"}]}
    return atomic_write(Path(root) / f"{name}{DBCONFIG_SUFFIX}",
                        json.dumps(config, indent=1) + "\n", overwrite=overwrite)
