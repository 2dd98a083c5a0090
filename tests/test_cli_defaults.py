"""Every DATASET form of the commands with its defaults only (issue 22): no optional flag
but the required ones, as a user types them from the README. ``cassi animate DATASET
--out DIR`` once crashed on its default stride and no test ran it.

The data are small, not the settings: one subject, one task, its pellet file cut to 0.3 s
after the first valid line (the leading untracked rows kept, as in every real file), its
sound cut to match, PAL.DAT, PHA.DAT and Headmeasures.txt as the synthetic corpus wrote
them. ``--jobs`` is left at its default (all cores): with one recording that is one
worker, this process; a copy of the recording under a second task name makes the jaw run
spawn its worker processes as the default does on any corpus. Each test checks what the outputs say against what the data are,
not only that the command exited 0.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import zoo

from cassi_fit import cli
from cassi_fit.pellets import MNI, MNM, first_valid_line
from cassi_fit.txy import PelletTrack, read_txy, write_txy
from cassi_fit.video import count_frames, media_info, slice_wav

pytestmark = pytest.mark.slow

SECONDS = 0.3  # after the first valid line: 44 frames, in the smallest frame bucket (64)
SUBJECT, TASK = "S01", "tp040"


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """``(dataset folder, the cut PelletTrack, its number of lines from the first valid
    one)``."""
    source = zoo.small_corpus(tmp_path_factory, n_subjects=1, tasks=(TASK,))
    root = tmp_path_factory.mktemp("tiny") / "data"
    (root / SUBJECT).mkdir(parents=True)
    shutil.copy(source / "Headmeasures.txt", root)
    for name in ("PAL.DAT", "PHA.DAT"):
        shutil.copy(source / SUBJECT / name, root / SUBJECT / name)
    track = read_txy(source / SUBJECT / "TP040.TXY")
    first = first_valid_line(track).index
    n = first + round(SECONDS / track.frame_step_s)
    cut = PelletTrack(track.times[:n], track.positions[:n], track.valid[:n])
    write_txy(root / SUBJECT / "TP040.TXY", cut)
    slice_wav(source / SUBJECT / "TP040.WAV", root / SUBJECT / "TP040.WAV", 0.0,
              float(cut.times[-1]) + cut.frame_step_s)
    return root, cut, n - first


def _cassi(*words) -> int:
    return cli.main([str(w) for w in words])


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_animate_dataset_with_its_defaults(tiny, tmp_path, capsys):
    """Every line from the first valid one (stride 1) in the table, an MP4 at the default
    60 fps with sound at 640x480 (all five views), one table row naming it."""
    root, cut, frames = tiny
    out = tmp_path / "videos"
    assert _cassi("animate", root, "--out", out) == 0, capsys.readouterr().err
    (row,) = _rows(out / "animate_corpus.csv")
    assert (row["subject"], row["task"], row["status"]) == (SUBJECT, TASK, "ok")
    assert int(row["stride"]) == 1 and int(row["frames"]) == frames
    video = out / row["video"]
    assert video == out / SUBJECT / f"{TASK}.mp4"
    assert abs(count_frames(video) - frames * cut.frame_step_s * 60) <= 1  # --fps 60
    info = media_info(video)
    assert info["audio"] and "640x480" in " ".join(info["streams"])
    assert info["duration"] == pytest.approx(frames * cut.frame_step_s, abs=0.03)
    low, high = float(row["tongue_volume_min_ml"]), float(row["tongue_volume_max_ml"])
    assert 50.0 < low <= high < 120.0  # an adult tongue's volume, kept while it moves
    assert f"1 of 1 videos written to {out}" in capsys.readouterr().out


def test_jaw_dataset_with_its_defaults(tiny, tmp_path, capsys):
    """The closed form (Eqs 1-7) on every line: its angles are the turns of the jaw
    pellets' line."""
    root, cut, frames = tiny
    out = tmp_path / "jaw"
    assert _cassi("jaw", root, "--out", out) == 0, capsys.readouterr().err
    (row,) = _rows(out / "jaw_corpus.csv")
    assert (row["status"], row["method"], row["converged"]) == ("ok", "closed-form", "true")
    assert int(row["frames"]) == len(cut.times)
    table = _rows(out / SUBJECT / f"{TASK}.jaw.csv")
    assert len(table) == len(cut.times)
    first = len(cut.times) - frames
    ok = np.array([r["status"] == "ok" for r in table])
    assert not ok[:first].any() and ok[first:].mean() > 0.8  # lead rows invalid
    theta = np.array([float(r["theta_deg"]) for r in table])
    # Eqs 1-3 by hand: the turn of the MNI-MNM line from the first valid line's, opening > 0
    line = cut.positions[:, MNI] - cut.positions[:, MNM]
    angle = np.arctan2(line[:, 1], line[:, 0])
    np.testing.assert_allclose(theta[ok], np.degrees(angle[first] - angle[ok]), atol=2e-6)
    assert float(row["theta_range_deg"]) == pytest.approx(np.ptp(theta[ok]), abs=1e-5)


def test_evaluate_dataset_with_its_defaults(tiny, tmp_path, monkeypatch, capsys):
    """``cassi evaluate DATASET`` writes ./evaluation/: the recording measured on every
    line with the default calibration, the subject rated."""
    root, _, frames = tiny
    monkeypatch.chdir(tmp_path)
    assert _cassi("evaluate", root) == 0, capsys.readouterr().err
    out = tmp_path / "evaluation"
    assert {p.name for p in out.iterdir() if not p.name.startswith(".")} >= {
        "evaluation_subjects.csv", "evaluation_recordings.csv", "evaluation.md"}
    (row,) = _rows(out / "evaluation_recordings.csv")
    assert (row["subject"], row["task"], row["status"]) == (SUBJECT, TASK, "ok")
    assert int(row["frames"]) == frames and int(row["stride"]) == 1
    assert row["calibration"] == "default" and row["collisions"] == "off"
    (subject,) = _rows(out / "evaluation_subjects.csv")
    ratings = {"EXCELLENT", "VERY GOOD", "GOOD", "FAIR"}
    for part in ("teeth", "lips", "tongue"):
        assert subject[f"{part}_rating"] in ratings, subject
    text = (out / "evaluation.md").read_text()
    assert "stride 1" in text and f"| {SUBJECT} | {TASK} |" in text


def test_calibrate_dataset_with_its_defaults(tiny, tmp_path, monkeypatch, capsys):
    """``cassi calibrate DATASET`` writes ./calibration/SUBJECT.calibration.json; the
    default (separate) method's scale is p/d on the first valid line (CASSI's step 2)."""
    from cassi_fit.deform import model_pellets
    from cassi_fit.face_model import load_model

    root, cut, _ = tiny
    monkeypatch.chdir(tmp_path)
    assert _cassi("calibrate", root) == 0, capsys.readouterr().err
    out = tmp_path / "calibration"
    (row,) = _rows(out / "calibration_corpus.csv")
    assert (row["subject"], row["status"]) == (SUBJECT, "ok")
    saved = json.loads((out / f"{SUBJECT}.calibration.json").read_text())
    model = load_model()
    sites = np.asarray(model_pellets(model, model.vertices))
    line = cut.positions[first_valid_line(cut).index]
    p_over_d = np.linalg.norm(sites[MNI] - sites[MNM]) / np.linalg.norm(line[MNI] - line[MNM])
    assert saved["subject"] == SUBJECT and saved["method"] == "separate"
    assert math.isclose(saved["scale"], p_over_d, rel_tol=1e-6), saved
    (summary,) = _rows(out / "calibration_summary.csv")
    assert summary["subject"] == SUBJECT



def test_jaw_dataset_default_jobs_spawn_workers_and_agree(tiny, tmp_path, capsys):
    """Two recordings and the default ``--jobs`` (all cores): worker processes on a
    machine with two cores or more; each recording's table is the one this process
    writes for it."""
    from cassi_fit.corpus import default_jobs

    root, _, _ = tiny
    two = tmp_path / "two"
    shutil.copytree(root, two)
    shutil.copy(two / SUBJECT / "TP040.TXY", two / SUBJECT / "TP041.TXY")
    assert _cassi("jaw", two, "--out", tmp_path / "jaw") == 0, capsys.readouterr().err
    workers = min(default_jobs(), 2)
    assert f"on {workers} worker(s)" in capsys.readouterr().out
    alone = tmp_path / "alone"
    assert _cassi("jaw", root, "--out", alone, "--jobs", 1) == 0
    expected = (alone / SUBJECT / f"{TASK}.jaw.csv").read_bytes()
    for task in (TASK, "tp041"):
        assert (tmp_path / "jaw" / SUBJECT / f"{task}.jaw.csv").read_bytes() == expected, task
    rows = _rows(tmp_path / "jaw" / "jaw_corpus.csv")
    assert [(r["task"], r["status"]) for r in rows] == [(TASK, "ok"), ("tp041", "ok")]
