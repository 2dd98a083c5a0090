"""``cassi info PATH``: subjects, tasks, frames and a validity report of XRMB or EMA data."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ._options import add_source_arguments, source_options


def register(subparsers) -> None:
    parser = subparsers.add_parser(
        "info",
        help="list subjects and tasks of XRMB or articulograph data, with a validity report",
        description="PATH is a dataset folder (one folder per subject, or flat names such as "
        "jw11_tp005.txy or fsew0_001.ema) or a single recording (XRMB .txy, EST Track, "
        "Carstens .pos, NDI Wave .tsv, mview .mat, .npy/.npz/.csv arrays; the format is "
        "detected by content). Prints subjects, tasks, frames, the first valid frame, "
        "per-pellet valid fractions, unmarked mistracks and the jaw pellet distance (MNI-MNM) "
        "spread; for articulograph data also the sensor roles, the head correction and its "
        "residual, the occlusal frame and each sensor's distance from the midsagittal plane "
        "(docs/EMA.md). --json gives, per role, the median position in the toolkit's frame.",
    )
    parser.add_argument("path", metavar="PATH", help="dataset folder or recording file")
    parser.add_argument("--json", action="store_true", help="print one JSON document instead")
    parser.add_argument(
        "--list", action="store_true", help="only list subjects and tasks (read no file)"
    )
    add_source_arguments(parser)
    parser.add_argument("--write-sensor-map", metavar="FILE", default=None,
                        help="articulograph files with numbered channels: propose a sensor map "
                        "from the data (roles with their evidence and confidence) and write it "
                        "to FILE as TOML to edit (PATH: a file, or a folder's first file)")
    parser.set_defaults(func=run)


def _medians(positions, valid, names) -> dict:
    """name -> median ``[x, y]`` mm over the frames where it is tracked, or None."""
    import numpy as np

    out = {}
    for j, name in enumerate(names):
        ok = valid[:, j].all(-1)
        out[name] = (None if not ok.any()
                     else [round(float(v), 3) for v in np.median(positions[ok, j], axis=0)])
    return out


def _describe(recording) -> dict:
    """JSON-ready summary of one loaded recording."""
    from cassi_fit.pellets import PELLET_NAMES
    from cassi_fit.quality import quality_report

    track = recording.track
    sensors = getattr(recording, "sensors", None)
    return {
        "path": str(recording.path),
        "format": "xrmb" if sensors is None else sensors.format,
        "frame_step_s": track.frame_step_s,
        "audio": None if recording.audio is None else str(recording.audio),
        "palate_points": None if recording.palate is None else len(recording.palate),
        "pharynx_points": None if recording.pharynx is None else len(recording.pharynx),
        "head_is_default": recording.head_is_default,
        "quality": quality_report(track).to_dict(),
        "median_mm": _medians(track.positions, track.valid, PELLET_NAMES),
        "extras_median_mm": _medians(track.extra_positions, track.extra_valid,
                                     track.extra_names),
        "sensors": None if sensors is None else sensors.to_dict(),
        "sound": _sound(recording),
        "labels": _labels(recording),
    }


def _sound(recording) -> dict | None:
    """The sound (beside the file or inside it: ``Recording.sound``) checked against the
    pellets (``sound.check_sound``), or its error; with where it was found."""
    import warnings

    from cassi_fit.errors import CassiError
    from cassi_fit.sound import check_sound

    sound = getattr(recording, "sound", None)
    if sound is None:
        return None
    found = {"source": sound.source, "kind": sound.kind}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the report carries the message
        try:
            return {**check_sound(sound, recording.track.length_s,
                                  accept_mismatch=True).to_dict(), **found}
        except CassiError as exc:
            return {"error": str(exc), **found}


def _labels(recording) -> dict:
    """The label files beside the recording and the tiers inside it, and the tier every
    output uses (``labels.recording_labels``) or why none can be."""
    import warnings

    from cassi_fit.errors import CassiError
    from cassi_fit.labels import TEXTGRID_SUFFIX, label_path_for, recording_labels, textgrid_tiers

    path = getattr(recording, "path", None)
    beside = None if path is None else label_path_for(path)
    inside = [{"tier": t.tier, "labels": len(t)} for t in getattr(recording, "labels", ())]
    tiers = []  # a TextGrid beside: its tiers, what --tier can name
    if beside is not None and beside.suffix.lower() == TEXTGRID_SUFFIX:
        try:
            tiers = [{"tier": name, "labels": n} for name, n in textgrid_tiers(beside)]
        except CassiError:
            tiers = []  # unreadable: the used tier's error says why
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            used = recording_labels(recording, accept_mismatch=True)
            used = None if used is None else {"tier": used.tier, "labels": len(used)}
        except CassiError as exc:
            used = {"error": str(exc)}
    return {"beside": None if beside is None else str(beside), "beside_tiers": tiers,
            "inside": inside, "used": used}


def _quietly(load, *args):
    """``load(*args)`` without the default-head-measures warning (the report shows it)."""
    import warnings

    from cassi_fit.dataset import DefaultHeadMeasuresWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load(*args)


def _load(load, *args) -> dict:
    """Describe a recording, or report its error (one bad file does not stop the listing)."""
    from cassi_fit.errors import CassiError

    try:
        return _describe(_quietly(load, *args))
    except CassiError as exc:
        return {"error": str(exc)}


def collect(path: Path, list_only: bool = False, *, sensor_map=None, layout=None, rate=None,
            bite_plane=None, tier=None) -> dict:
    """The whole report as a JSON-ready dict (a folder or a single recording file); the
    keywords are :func:`cassi_fit.dataset.load_recording`'s, for articulograph files."""
    from functools import partial

    from cassi_fit.dataset import Dataset, load_recording
    from cassi_fit.errors import MissingDataError

    if isinstance(layout, str) and "," in layout:
        layout = [c.strip() for c in layout.split(",") if c.strip()]
    from cassi_fit.ema.emu import is_bundle_folder

    if ((path.exists() or path.is_symlink()) and not path.is_dir()) or is_bundle_folder(path):
        # a file (load_recording refuses a FIFO, a device, a broken or looping link)
        load = partial(load_recording, sensor_map=sensor_map, layout=layout, rate=rate,
                       bite_plane=bite_plane, tier=tier)
        rec = _quietly(load, path)
        info = _describe(rec)
        return {"path": str(path), "kind": "file", "subject": rec.subject, "task": rec.task, **info}
    if not path.is_dir():
        raise MissingDataError(f"{path}: no such file or folder")
    ds = Dataset(path, sensor_map=sensor_map, tier=tier)
    ds.check_selection()  # nothing found: one line naming the folder and what was looked for
    subjects = {}
    for subject in ds.subjects():
        tasks = {}
        for task in ds.tasks(subject):
            if list_only:
                tasks[task] = {"path": str(ds.pellet_path(subject, task))}
            else:
                tasks[task] = _load(ds.load, subject, task)
        subjects[subject] = tasks
    return {"path": str(path), "kind": "dataset", "n_subjects": len(subjects),
            "n_recordings": len(ds), "subjects": subjects}  # fmt: skip


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def _mm(x, digits=2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _print_file(report: dict, out) -> None:
    q = report["quality"]
    first = q["first_valid_frame"]
    print(f"{report['subject']} {report['task']}  {report['path']}", file=out)
    paper = q.get("first_complete_frame")
    moved = f" (moved from {paper}: mistracked)" if paper is not None and paper != first else ""
    never = [p for p in ("MNI", "MNM") if not q["valid_fraction"].get(p)]
    if first is None and never:  # e.g. an articulograph with one jaw sensor
        moved = f" (jaw pellet {', '.join(never)} never tracked)"
    print(f"  frames {q['n_frames']}  duration {q['duration_s']:.3f} s  first valid frame "
          f"{'-' if first is None else first}{moved}  first jaw frame "
          f"{'-' if q['first_jaw_frame'] is None else q['first_jaw_frame']}", file=out)  # fmt: skip
    print(f"  palate {report['palate_points'] or '-'} points  pharynx "
          f"{report['pharynx_points'] or '-'} points  head measures "
          f"{'DEFAULTS' if report['head_is_default'] else 'from file'}  audio "
          f"{report['audio'] or ('in the file' if report.get('sound') else '-')}",
          file=out)  # fmt: skip
    print("  pellet  valid%  mistracked  reasons", file=out)
    reasons = q.get("mistrack_reasons") or {}
    for name, frac in q["valid_fraction"].items():
        why = ", ".join(f"{r} {c}" for r, c in reasons.get(name, {}).items())
        print(f"  {name:<6}  {_pct(frac):>6}  {q['n_mistracked'][name]:>10}  {why}".rstrip(),
              file=out)
    print(f"  all     {_pct(q['all_valid_fraction']):>6}{_of_tracked(q)}", file=out)
    print(f"  jaw distance MNI-MNM: median {_mm(q['jaw_distance_median_mm'])} mm, "
          f"SD {_mm(q['jaw_distance_sd_mm'], 3)} mm", file=out)  # fmt: skip
    sound = report.get("sound")
    if sound:
        where = ("" if sound.get("kind") == "wav beside"
                 else f" ({sound['kind']}: {sound['source']})")
        said = sound.get("error") or sound["message"] or "length fits the pellets"
        print(f"  sound{where}: {said}", file=out)
    _print_labels(report.get("labels"), out)
    if report.get("sensors"):
        _print_sensors(report, out)


def _of_tracked(q: dict) -> str:
    """What ``all`` is a share of, where the file never tracks some pellets (an
    articulograph without a sensor for them): empty when it tracks all of them."""
    never = q.get("never_tracked") or ()
    if not never:
        return ""
    return (f" (of the {len(q['valid_fraction']) - len(never)} pellets tracked; never "
            f"tracked: {', '.join(never)})")


def _print_labels(labels: dict | None, out) -> None:
    """Where the labels are: a file beside, tiers inside the file, the tier used."""
    if not labels or not (labels["beside"] or labels["inside"]):
        return
    parts = [f"beside: {labels['beside']}"] if labels["beside"] else []
    if labels.get("beside_tiers"):
        parts[-1] += " (tiers: " + ", ".join(f"{t['tier']} ({t['labels']})"
                                             for t in labels["beside_tiers"]) + ")"
    if labels["inside"]:
        parts.append("in the file: " + ", ".join(f"{t['tier']} ({t['labels']})"
                                                 for t in labels["inside"]))
    used = labels["used"] or {}
    parts.append(f"used: {used['tier']}" if "tier" in used else f"error: {used.get('error')}")
    print(f"  labels: {'; '.join(parts)}", file=out)


def _print_sensors(report: dict, out) -> None:
    """The articulograph part: roles, references, head correction, frame, distances."""
    s = report["sensors"]
    print(f"  articulograph: {s['format']}, {s['dims']}D, {s['rate_hz']:g} Hz, units "
          f"{s['units']}; file axes: {s['file_axes']}", file=out)
    print(f"  sensor map: {s['sensor_map']}", file=out)
    medians = report["median_mm"]
    print("  role  sensor      median x, y (mm, toolkit frame)", file=out)
    for role, sensor in s["roles"].items():
        where = medians.get(role)
        at = "-" if where is None else f"{where[0]:8.2f} {where[1]:8.2f}"
        print(f"  {role:<4}  {sensor or '(none)':<10}  {at}", file=out)
    for name, where in report["extras_median_mm"].items():
        at = "-" if where is None else f"{where[0]:8.2f} {where[1]:8.2f}"
        print(f"  extra {name:<10}  {at}", file=out)
    r = s["head_residual_mm"]
    print(f"  head correction: {s['head_correction']}", file=out)
    if r["median"] is not None:
        rot, shift = s["head_rotation_deg"], s["head_translation_mm"]
        print(f"    residual mm: median {r['median']:.3f}, 95% {r['p95']:.3f}, max "
              f"{r['max']:.3f}; head motion removed: up to {rot['max']:.2f} deg, "
              f"{shift['max']:.2f} mm", file=out)
    if s["frames_without_references"]:
        print(f"    {s['frames_without_references']} frame(s) without the references "
              "(untracked)", file=out)
    print(f"  occlusal frame: {s['frame_source']}", file=out)
    if s["midsagittal_distance_mm"]:
        dist = ", ".join(f"{k} {v:+.1f}" for k, v in s["midsagittal_distance_mm"].items())
        print(f"  distance from the midsagittal plane (mm, + left): {dist}", file=out)
    for note in s["notes"]:
        print(f"  note: {note}", file=out)


_COLUMNS = ("subject", "task", "frames", "dur_s", "first", "all%", "jaw_mm", "jaw_sd", "mistr")


def _row(subject: str, task: str, entry: dict) -> list[str]:
    if "error" in entry:
        return [subject, task, f"error: {entry['error']}"]
    if "quality" not in entry:
        return [subject, task, entry["path"]]
    q = entry["quality"]
    first = q["first_valid_frame"]
    return [subject, task, str(q["n_frames"]), f"{q['duration_s']:.2f}",
            "-" if first is None else str(first), _pct(q["all_valid_fraction"]),
            _mm(q["jaw_distance_median_mm"]), _mm(q["jaw_distance_sd_mm"], 3),
            str(sum(q["n_mistracked"].values()))]  # fmt: skip


def _print_dataset(report: dict, out) -> None:
    print(f"{report['path']}: {report['n_subjects']} subject(s), "
          f"{report['n_recordings']} recording(s)", file=out)  # fmt: skip
    for subject, tasks in report["subjects"].items():
        loaded = [e for e in tasks.values() if "quality" in e]
        extra = ""
        if loaded:
            e = loaded[0]
            extra = (f"; palate {e['palate_points'] or '-'} points, pharynx "
                     f"{e['pharynx_points'] or '-'}, head measures "
                     f"{'DEFAULTS' if e['head_is_default'] else 'from file'}")  # fmt: skip
        print(f"  {subject}: {len(tasks)} task(s){extra}", file=out)
    rows = [_row(s, t, e) for s, tasks in report["subjects"].items() for t, e in tasks.items()]
    header = (
        list(_COLUMNS)
        if any(len(r) == len(_COLUMNS) for r in rows)
        else ["subject", "task", "path"]
    )
    table = [header] + [r for r in rows if len(r) == len(header)]
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    for r in [header] + rows:
        if len(r) == len(_COLUMNS):
            r = [c.ljust(w) for c, w in zip(r, widths, strict=True)]
        else:  # --list (path) or an error: the rest of the line
            r = [r[0].ljust(widths[0]), r[1].ljust(widths[1]), r[2]]
        print("  " + "  ".join(r).rstrip(), file=out)
    _print_never_tracked(report, out)


def _print_never_tracked(report: dict, out) -> None:
    """Below the table, where some file never tracks some pellets: ``all%`` is the share of
    frames with every pellet the file tracks (``QualityReport.all_valid_fraction``)."""
    from cassi_fit.pellets import PELLET_NAMES

    files = [e["quality"].get("never_tracked") or () for tasks in report["subjects"].values()
             for e in tasks.values() if "quality" in e]
    never = {p for names in files for p in names}
    if never:
        names = ", ".join(p for p in PELLET_NAMES if p in never)
        print(f"  all%: of the pellets each file tracks; {sum(map(bool, files))} of "
              f"{len(files)} recording(s) never track some ({names})", file=out)


def _write_map(path: Path, out_path: str, out) -> int:
    """``--write-sensor-map``: the proposal for PATH (or its folder's first file)."""
    from cassi_fit.ema.identify import write_proposed_map

    if path.is_dir():
        from cassi_fit.dataset import Dataset

        ds = Dataset(path)
        ds.check_selection()
        subject = ds.subjects()[0]
        path = ds.pellet_path(subject, ds.tasks(subject)[0])
    proposal = write_proposed_map(path, out_path)
    print(f"{out_path}: sensor map proposed from {path} (check it; NOT SURE lines are "
          "commented out):", file=out)
    for g in proposal.guesses:
        mark = "" if g.sure else "  NOT SURE"
        print(f"  {g.channel:<8} {g.role:<12} {g.confidence:.2f}{mark}  {g.evidence}", file=out)
    for note in proposal.notes:
        print(f"  note: {note}", file=out)
    return 0


def run(args) -> int:
    if getattr(args, "write_sensor_map", None):
        return _write_map(Path(args.path), args.write_sensor_map, sys.stdout)
    report = collect(Path(args.path), list_only=args.list, **source_options(args))
    out = sys.stdout
    if args.json:
        json.dump(report, out, indent=2)
        print(file=out)
    elif report["kind"] == "file":
        _print_file(report, out)
    else:
        _print_dataset(report, out)
    failed = report["kind"] == "dataset" and any(
        "error" in e for ts in report["subjects"].values() for e in ts.values()
    )
    return 2 if failed else 0
