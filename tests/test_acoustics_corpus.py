"""``cassi acoustics DATASET --out DIR``: every recording of a dataset heard, and the
dataset's tables, as messy as a lab's: one subject with sound and phone labels, one with
sound and only a words tier, one with no sound at all."""

import csv
import shutil

import numpy as np
import pytest

from cassi_fit import cli
from cassi_fit.acoustics_corpus import RECORDINGS_NAME, SEGMENTS_NAME, SUMMARY_NAME, hear
from cassi_fit.dataset import Dataset
from cassi_fit.labels import recording_labels
from cassi_fit.run_spec import run_spec
from cassi_fit.synth import generate_corpus


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _lab(path, length_s, labels):
    """``labels`` evenly over the recording, HTK-style ``start end label`` in seconds."""
    edges = np.linspace(0.0, length_s, len(labels) + 1)
    path.write_text("".join(f"{a:.4f} {b:.4f} {lab}\n"
                            for a, b, lab in zip(edges[:-1], edges[1:], labels, strict=True)))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = generate_corpus(tmp_path_factory.mktemp("acoustics") / "corpus", n_subjects=2,
                           tasks="tp040")
    one = root / "S01"
    for wav in (root / "S02").glob("*.[Ww][Aa][Vv]"):  # S02: no sound
        wav.unlink()
    ds = Dataset(root)
    length = ds.load("S01", "tp040").track.length_s
    _lab(one / "TP040.lab", length, ["sil", "a", "s", "i:", "t", "aI", "sil"])
    # a third subject: S01's recording again, labelled with words only
    words = root / "S03"
    shutil.copytree(one, words)
    _lab(words / "TP040.lab", length, ["the", "cat", "sat"])
    return root


def test_a_dataset_is_heard_recording_by_recording_and_summed_up_per_subject(dataset, tmp_path,
                                                                             capsys):
    out = tmp_path / "heard"
    status = cli.main(["acoustics", str(dataset), "--out", str(out), "--jobs", "1", "--quiet"])
    printed = capsys.readouterr()
    assert status == 1  # S02 has no sound: its row failed, the others were heard
    recordings = {r["subject"]: r for r in _rows(out / RECORDINGS_NAME)}
    assert recordings["S02"]["status"] == "failed" and "no sound" in recordings["S02"]["error"]
    assert "\n" not in recordings["S02"]["error"]
    assert recordings["S01"]["status"] == "ok" and int(recordings["S01"]["segments"]) == 3
    assert recordings["S03"]["status"] == "ok" and recordings["S03"]["segments"] == "0"
    assert "no vowel among the 3 labels" in recordings["S03"]["note"]
    assert (out / "S01" / "tp040.acoustics.csv").is_file()
    assert (out / "S01" / "tp040.acoustics.segments.csv").is_file()
    assert not (out / "S03" / "tp040.acoustics.segments.csv").exists()

    # the dataset's segments are S01's, each as one recording is heard (the same path)
    segments = _rows(out / SEGMENTS_NAME)
    assert [(s["subject"], s["vowel"], s["quality"]) for s in segments] == [
        ("S01", "a", "a"), ("S01", "i:", "i"), ("S01", "aI", "aI")]
    recording = Dataset(dataset).load("S01", "tp040")
    alone = hear(recording, run_spec(None), labels=recording_labels(recording))
    for got, want in zip(segments, alone.acoustics.segment_rows(), strict=True):
        assert int(got["frames"]) == want["frames"] and int(got["scored"]) == want["scored"]
        for f in ("F1", "F2", "F3"):
            if want[f"{f}_error"] is None:
                assert got[f"{f}_error"] == ""
            else:
                assert float(got[f"{f}_error"]) == pytest.approx(want[f"{f}_error"], abs=6e-5)

    # per subject and quality, then over all qualities: medians of the segments' errors
    summary = _rows(out / SUMMARY_NAME)
    assert [(r["subject"], r["quality"]) for r in summary] == [
        ("S01", "a"), ("S01", "aI"), ("S01", "i"), ("S01", "all")]
    overall = summary[-1]
    scored = [s for s in segments if int(s["scored"]) > 0]
    assert int(overall["segments"]) == 3 and int(overall["segments_scored"]) == len(scored)
    for f in ("F1", "F2", "F3"):
        errors = [float(s[f"{f}_error"]) for s in scored if s[f"{f}_error"]]
        if errors:
            assert float(overall[f"{f}_median_abs_error_pct"]) == pytest.approx(
                100 * np.median(np.abs(errors)), abs=0.051)
            assert float(overall[f"{f}_median_error_pct"]) == pytest.approx(
                100 * np.median(errors), abs=0.051)
    for f in ("F1", "F2", "F3"):  # the recording's row: its segments' median, as the subject's
        assert (float(recordings["S01"][f"{f}_median_abs_error_pct"])
                == float(overall[f"{f}_median_abs_error_pct"]))
    assert "| S01 | all | 3 |" in printed.out and "2 of 3 recordings heard" in printed.out
    assert (out / "acoustics_summary.md").is_file()

    # the tables are outputs: a second run is refused, --resume takes what is done
    assert cli.main(["acoustics", str(dataset), "--out", str(out), "--jobs", "1",
                     "--quiet"]) == 2
    assert "--resume" in capsys.readouterr().err


def test_one_recording_options_and_dataset_options_are_not_mixed(dataset, tmp_path, capsys):
    assert cli.main(["acoustics", str(dataset), "--out", str(tmp_path / "o"),
                     "--csv", str(tmp_path / "x.csv")]) == 2
    assert "--csv and --plot are for one recording" in capsys.readouterr().err
    txy = next((dataset / "S01").glob("*.TXY"))
    assert cli.main(["acoustics", str(txy), "--out", str(tmp_path / "o")]) == 2
    assert "--out DIR is for a dataset folder" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
