"""Stage 6 of the synthetic corpus, files: :func:`generate_corpus` writes the real formats
through the toolkit's writers plus the truth files, into a temporary folder moved into
place at the end; the default corpus's cache (:func:`ensure_default_corpus`, keyed by
:data:`GENERATOR_VERSION`); reading truth back from a corpus folder (:func:`load_truth`,
:func:`load_anatomy`), refused while the corpus is incomplete."""

from __future__ import annotations

import os
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import CassiError, MissingDataError, OutputExistsError
from ._anatomy import (
    JAW_KINEMATICS,
    SubjectAnatomy,
    _check_family,
    default_jaw_kinematics,
    make_subject,
)
from ._audio import _write_wav, synth_audio
from ._kinematics import JawTruth
from ._measurement import DEFAULT_NOISE_MM, MAX_NOISE_SCALE, NOISE_FAMILIES, _simulate
from ._tasks import DEFAULT_TASKS, TASKS, get_task
from ._truth import _anatomy_json, _parse_anatomy, _parse_truth, _truth_text

GENERATOR_VERSION = 6  # bump when the generated numbers change (invalidates the cache)


def _find_ci(folder: Path, name: str) -> Path | None:
    """The entry of ``folder`` called ``name`` ignoring case, or None."""
    if not folder.is_dir():
        return None
    exact = folder / name
    if exact.exists():
        return exact
    matches = sorted(p for p in folder.iterdir() if p.name.lower() == name.lower())
    return matches[0] if matches else None


def load_truth(root: str | os.PathLike, subject: str, task: str) -> JawTruth:
    """Read the ground truth of ``subject``'s ``task`` from a corpus folder ``root``.

    Reads ``root/<subject>/<task>.truth.csv`` (names case-insensitive). Raises
    MissingDataError when absent or when the corpus is incomplete (its README.txt lacks
    the completion line: an interrupted generation), DataFormatError when malformed.
    """
    from .._io import register_input

    _check_corpus(Path(root))
    folder = _find_ci(Path(root), str(subject))
    path = _find_ci(folder, f"{task}.truth.csv") if folder is not None else None
    if path is None:
        raise MissingDataError(f"{Path(root) / str(subject)}: no ground truth for task {task!r}")
    register_input(path)
    return _parse_truth(path, path.read_text(encoding="utf-8"))


def load_anatomy(root: str | os.PathLike, subject: str) -> SubjectAnatomy:
    """Read ``root/<subject>/anatomy.json`` written by :func:`generate_corpus` (refused,
    MissingDataError, when the corpus is incomplete, as :func:`load_truth`)."""
    from .._io import register_input

    _check_corpus(Path(root))
    folder = _find_ci(Path(root), str(subject))
    path = _find_ci(folder, "anatomy.json") if folder is not None else None
    if path is None:
        raise MissingDataError(f"{Path(root) / str(subject)}: no anatomy.json")
    register_input(path)
    return _parse_anatomy(path, path.read_text(encoding="utf-8"))


def subject_names(n_subjects: int) -> list[str]:
    """``S01``, ``S02``, ... (never the real database's JW names)."""
    return [f"S{i + 1:02d}" for i in range(n_subjects)]


def _file_names(index: int) -> dict[str, str]:
    """Upper-case file names for odd-numbered subjects (S01, S03, ...), lower for even:
    the real distribution mixes both, and readers must not care."""
    upper = index % 2 == 0
    case = str.upper if upper else str.lower
    return {
        "pal": case("PAL.DAT"),
        "pha": case("PHA.DAT"),
        "txy": case(".txy"),
        "wav": case(".wav"),
    }


def _recording_seed(seed: int, index: int, task: str) -> list[int]:
    return [int(seed), 2, index, zlib.crc32(task.encode())]


def _corpus_plan(out_dir: Path, names, tasks, audio):
    """``[(subject index, name, task or None, {kind: path})]`` of every file to write."""
    plan = []
    for i, name in enumerate(names):
        fn, folder = _file_names(i), out_dir / name
        plan.append((i, name, None, {"pal": folder / fn["pal"], "pha": folder / fn["pha"],
                                     "anatomy": folder / "anatomy.json"}))  # fmt: skip
        for task in tasks:
            stem = task.upper() if fn["txy"] == ".TXY" else task
            files = {"txy": folder / f"{stem}{fn['txy']}", "truth": folder / f"{task}.truth.csv"}
            if audio and TASKS[task].audio:
                files["wav"] = folder / f"{stem}{fn['wav']}"
            plan.append((i, name, task, files))
    return plan


COMPLETE_LINE = "complete: yes"  # the README's last line, written last of all files


def _readme(n_subjects, seed, tasks, noise_scale, audio, families, noise_family) -> str:
    names = subject_names(n_subjects)
    lines = [
        "cassi_fit synthetic XRMB corpus (NOT real data)",
        "",
        "Made by cassi_fit.synth.generate_corpus / `cassi synth`; see docs/SYNTHETIC.md.",
        f"generator_version: {GENERATOR_VERSION}",
        f"seed: {seed}",
        f"subjects: {n_subjects} ({', '.join(names)})",
        f"tasks: {', '.join(tasks)}",
        f"noise_scale: {noise_scale}",
        f"noise_family: {noise_family}",
        "jaw_kinematics: " + ", ".join(f"{n} {f}" for n, f in zip(names, families, strict=True)),
        f"audio: {'yes' if audio else 'no'}",
        "",
        "Per subject folder: pellet files (.txy, real format), PAL.DAT, PHA.DAT, audio (.wav,",
        "16 kHz, speech tasks), <task>.truth.csv (per frame: true jaw angle, translation,",
        "pivot, condyle, noise-free pellets, dropout and mistrack flags) and anatomy.json.",
        "Headmeasures.txt holds every subject's head measures.",
        "The last line below is written after every other file: without it the corpus is",
        "incomplete (generation was interrupted) and the readers refuse it.",
        COMPLETE_LINE,
    ]
    return "\n".join(lines) + "\n"


def _families(n_subjects: int, jaw_kinematics) -> list[str]:
    """Each subject's jaw-kinematics family: None or "mixed" for the default cycle
    (:func:`default_jaw_kinematics`), one family for all, or a comma-separated string /
    sequence of families cycled over the subjects."""
    names = subject_names(n_subjects)
    if jaw_kinematics is None or jaw_kinematics == "mixed":
        return [default_jaw_kinematics(n) for n in names]
    if isinstance(jaw_kinematics, str):
        jaw_kinematics = [f.strip() for f in jaw_kinematics.split(",") if f.strip()]
    cycle = [_check_family(f, JAW_KINEMATICS, "jaw kinematics") for f in jaw_kinematics]
    if not cycle:
        raise CassiError("no jaw kinematics family given")
    return [cycle[i % len(cycle)] for i in range(n_subjects)]


def generate_corpus(
    out_dir: str | os.PathLike,
    *,
    n_subjects: int = 15,
    seed: int = 0,
    tasks: str | Sequence[str] | None = None,
    noise_scale: float = 1.0,
    audio: bool = True,
    overwrite: bool = False,
    jaw_kinematics: str | Sequence[str] | None = None,
    noise_family: str = "realistic",
) -> Path:
    """Write a synthetic corpus to ``out_dir`` and return its path.

    ``tasks``: task names (default ``DEFAULT_TASKS``); ``noise_scale`` (0 to
    ``MAX_NOISE_SCALE``) multiplies the default measurement noise (0 = noise-free,
    dropouts and mistracks stay); ``noise_family`` one of :data:`NOISE_FAMILIES`;
    ``jaw_kinematics`` None / "mixed" (the default cycle over subjects: S01 physiological,
    S02 fixed-condyle, S03 thrust, ...), one of :data:`JAW_KINEMATICS` for every subject,
    or several (comma-separated or a sequence) cycled over the subjects; ``audio`` writes
    a ``.wav`` for speech tasks. Every argument is checked, and existing files refused
    (OutputExistsError, unless ``overwrite``), before anything is written. The corpus is
    written into a temporary sibling folder and moved into place at the end, README.txt
    (whose last line marks a complete corpus) last; an interrupted run leaves nothing.
    Deterministic: the same arguments give byte-identical files, and each recording
    depends only on (seed, subject, task, its family, the noise options).
    """
    import shutil
    import tempfile

    out_dir = Path(out_dir)
    tasks = _check_arguments(n_subjects, seed, tasks, noise_scale, audio)
    families = _families(n_subjects, jaw_kinematics)
    noise_family = _check_family(noise_family, NOISE_FAMILIES, "noise family")
    names = subject_names(n_subjects)
    relative = _corpus_plan(Path(), names, tasks, audio)
    if not overwrite:
        for rel in [Path("README.txt"), Path("Headmeasures.txt"),
                    *(p for *_, files in relative for p in files.values())]:  # fmt: skip
            if (out_dir / rel).exists():
                raise OutputExistsError(
                    f"{out_dir / rel}: file exists (pass overwrite=True / --force)"
                )
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputExistsError(f"{out_dir}: exists and is not a folder")
    if out_dir.is_dir():  # never into a real dataset, whatever overwrite says (issue 24)
        from ._foreign import refuse_foreign_data

        refuse_foreign_data(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.partial-", dir=out_dir.parent))
    try:
        _chmod_as_umask(tmp)
        options = (seed, tasks, noise_scale, audio, families, noise_family)
        _write_corpus(tmp, names, _corpus_plan(tmp, names, tasks, audio), options)
        from ._foreign import move_into_place

        move_into_place(tmp, out_dir)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return out_dir


def _chmod_as_umask(folder: Path) -> None:
    """``mkdtemp`` makes a 0700 folder; the corpus gets the user's normal folder mode."""
    mask = os.umask(0)
    os.umask(mask)
    folder.chmod(0o777 & ~mask)


def _write_corpus(root: Path, names, plan, options) -> None:
    """Every file of the corpus into ``root`` (a fresh folder), README.txt last."""
    from .._io import atomic_write
    from ..headmeasures import write_headmeasures
    from ..outlines import write_outline
    from ..txy import write_txy

    seed, tasks, noise_scale, audio, families, noise_family = options
    anatomies = {}
    for i, name, task, files in plan:
        if task is None:
            rng = np.random.default_rng([int(seed), 1, i])
            anatomy = make_subject(name, rng, jaw_kinematics=families[i])
            anatomies[name] = anatomy
            write_outline(files["pal"], anatomy.palate, overwrite=True)
            write_outline(files["pha"], anatomy.pharynx, overwrite=True)
            atomic_write(files["anatomy"], _anatomy_json(anatomy), overwrite=True)
            continue
        anatomy = anatomies[name]
        rec_seed = _recording_seed(seed, i, task)
        noise_mm = noise_scale * DEFAULT_NOISE_MM
        track, truth, controls, _ = _simulate(
            anatomy, task, rec_seed, noise_mm, None, True, True, noise_family
        )
        write_txy(files["txy"], track, overwrite=True)
        comment = (f"cassi_fit synthetic ground truth; subject {name}; task {task}; seed {seed};"
                   f" jaw kinematics {anatomy.jaw_kinematics}; noise {noise_family}")  # fmt: skip
        atomic_write(files["truth"], _truth_text(truth, comment), overwrite=True)
        if "wav" in files:
            rng = np.random.default_rng([*rec_seed, 3])
            samples = synth_audio(controls, truth.times, anatomy.f0_hz, rng)
            _write_wav(files["wav"], samples, overwrite=True)
    heads = {name: a.head for name, a in anatomies.items()}
    write_headmeasures(root / "Headmeasures.txt", heads, overwrite=True)
    readme = _readme(len(names), seed, tasks, noise_scale, audio, families, noise_family)
    atomic_write(root / "README.txt", readme, overwrite=True)


def _check_arguments(n_subjects, seed, tasks, noise_scale, audio) -> tuple[str, ...]:
    """Validate :func:`generate_corpus`'s arguments; returns the task names (lower case).

    Every option out of range is refused here, before anything is written.
    """
    if not isinstance(n_subjects, (int, np.integer)) or not 1 <= n_subjects <= 99:
        raise CassiError(f"n_subjects must be an integer from 1 to 99, got {n_subjects!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not (
        0 <= seed < 2**63
    ):
        raise CassiError(f"seed must be an integer from 0 to 2**63 - 1, got {seed!r}")
    if not (
        isinstance(noise_scale, (int, float, np.number))
        and np.isfinite(noise_scale)
        and 0 <= noise_scale <= MAX_NOISE_SCALE
    ):
        raise CassiError(
            f"noise_scale must be a number from 0 to {MAX_NOISE_SCALE:g} (the default noise "
            f"times at most {MAX_NOISE_SCALE:g}: > 2 mm per coordinate is not a pellet "
            f"track), got {noise_scale!r}"
        )
    if not isinstance(audio, bool):
        raise CassiError(f"audio must be True or False, got {audio!r}")
    if tasks is None:
        return DEFAULT_TASKS
    if isinstance(tasks, str):
        tasks = [t for t in tasks.split(",") if t.strip()]
    names = tuple(dict.fromkeys(get_task(t).name for t in tasks))
    if not names:
        raise CassiError("no tasks given")
    return names


# ---------------------------------------------------------------- the default corpus
DEFAULT_CORPUS_SEED = 0
_DEFAULT_CORPUS_ARGS = {"n_subjects": 15, "seed": DEFAULT_CORPUS_SEED}


def default_corpus_dir() -> Path:
    """Where the default corpus lives: ``$CASSI_SYNTH_DIR`` if set, else
    ``$XDG_CACHE_HOME/cassi_fit/synthetic-v<version>`` (``~/.cache`` by default)."""
    override = os.environ.get("CASSI_SYNTH_DIR")
    if override:
        return Path(override).expanduser()
    cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache).expanduser() / "cassi_fit" / f"synthetic-v{GENERATOR_VERSION}"


def corpus_status(folder: str | os.PathLike) -> str:
    """``"complete"`` (README.txt of this generator version ending in the completion line),
    ``"stale"`` (complete, another generator version), ``"incomplete"`` (a README without
    the completion line: generation was interrupted) or ``"absent"`` (no README.txt)."""
    readme = Path(folder) / "README.txt"
    if not readme.is_file():
        return "absent"
    text = readme.read_text(encoding="utf-8", errors="replace")
    if not text.rstrip("\n").endswith(COMPLETE_LINE):
        return "incomplete"
    current = f"generator_version: {GENERATOR_VERSION}\n" in text
    return "complete" if current else "stale"


def _is_complete(folder: Path) -> bool:
    return corpus_status(folder) == "complete"


def _check_corpus(root: Path) -> None:
    """Refuse to read ground truth from a corpus whose writing did not finish."""
    status = corpus_status(root)
    if status in ("absent", "incomplete"):
        raise MissingDataError(
            f"{root}: not a complete synthetic corpus (README.txt "
            f"{'missing' if status == 'absent' else 'lacks its last line'}: its generation "
            "was interrupted?); generate it again with `cassi synth --force`"
        )


def ensure_default_corpus() -> Path:
    """The default corpus (15 subjects, default tasks, seed 0), generated if absent.

    :func:`generate_corpus` writes into a temporary sibling folder and renames it into
    place, so a crash or a second process never leaves a half-written corpus behind; a
    folder that is there but not complete (interrupted, or of another generator version)
    is refused, not silently reused.
    """
    target = default_corpus_dir()
    if _is_complete(target):
        return target
    if target.exists() and any(target.iterdir()):
        raise OutputExistsError(
            f"{target}: exists but is not a complete synthetic corpus of this version "
            f"({corpus_status(target)}); remove it or point CASSI_SYNTH_DIR elsewhere"
        )
    try:
        generate_corpus(target, **_DEFAULT_CORPUS_ARGS, overwrite=False)
    except (OSError, OutputExistsError):
        if not _is_complete(target):  # another process may have finished it meanwhile
            raise
    return target
