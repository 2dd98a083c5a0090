"""A dataset's sensor map reaches every corpus command (issue 28: "every command takes it").

A lab-like AG501 session (numbered channels ``Ch1..Ch13``, no map beside the files; its true
map is written as ``truth_sensors.toml``, a name the toolkit does not look for): without
a map every recording fails with the one line saying what to give; with ``--sensor-map``
the dataset forms read it exactly as one file is read. The options that describe one
file are refused for a dataset instead of being silently dropped."""

import csv
import shutil

import pytest

from cassi_fit import cli
from cassi_fit.corpus import dataset_items, load_item
from cassi_fit.dataset import Dataset
from cassi_fit.pellets import pellet_index


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("lab") / "corpus"
    assert cli.main(["synth", str(root), "--format", "ag501", "--lab-like", "--subjects", "1",
                     "--no-audio"]) == 0
    (speaker,) = [p for p in root.iterdir() if p.is_dir()]
    assert sorted(p.suffix for p in speaker.iterdir() if p.suffix in (".pos", ".wav")) == [
        ".pos", ".pos"]  # --no-audio: no sound beside the files
    truth = root.parent / "lab_map.toml"  # kept away from the files: only the option gives it
    shutil.move(speaker / "truth_sensors.toml", truth)
    return root, truth


def _rows(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_the_items_carry_the_map_and_a_worker_reads_with_it(session):
    root, truth = session
    items = dataset_items(Dataset(root, sensor_map=str(truth)))
    assert items and all(i.sensor_map == str(truth) for i in items)
    per_subject = dataset_items(Dataset(root, sensor_map=str(truth)), per_subject=True)
    assert [i.sensor_map for i in per_subject] == [str(truth)]
    recording = load_item(items[0], quiet=True)
    valid = recording.track.valid.all(axis=-1)  # (frames, pellets)
    for role in ("UL", "LL", "T1", "MNI"):
        assert valid[:, pellet_index(role)].mean() > 0.9, role
    # without it the same item is the one line naming what to give
    bare = dataset_items(root)[0]
    assert bare.sensor_map is None and bare == items[0]  # the map is no part of its identity
    with pytest.raises(Exception, match="give a sensor map"):
        load_item(bare, quiet=True)


def test_cassi_jaw_on_the_dataset_uses_the_map(session, tmp_path, capsys):
    root, truth = session
    assert cli.main(["jaw", str(root), "--out", str(tmp_path / "bare"), "--jobs", "1"]) == 1
    assert "give a sensor map" in capsys.readouterr().err
    failed = _rows(tmp_path / "bare" / "jaw_corpus.csv")
    assert [r["status"] for r in failed] == ["failed", "failed"]
    assert all("give a sensor map" in r["error"] for r in failed)
    assert cli.main(["jaw", str(root), "--out", str(tmp_path / "mapped"), "--jobs", "1",
                     "--sensor-map", str(truth)]) == 0
    rows = _rows(tmp_path / "mapped" / "jaw_corpus.csv")
    assert len(rows) == 2 and {r["status"] for r in rows} == {"ok"}
    assert all(int(r["frames_ok"]) > 0.9 * int(r["frames"]) for r in rows)


@pytest.mark.parametrize("command", [["jaw", "--out", "{out}"], ["animate", "--out", "{out}"],
                                     ["calibrate", "--out", "{out}"], ["evaluate", "--out", "{out}"]])
@pytest.mark.parametrize("option", [["--layout", "sparc"], ["--rate", "250"],
                                    ["--bite-plane", "bite.pos"]])
def test_one_file_options_are_refused_for_a_dataset(session, tmp_path, capsys, command, option):
    root, _ = session
    argv = [command[0], str(root), *(a.format(out=tmp_path / "o") for a in command[1:]), *option]
    assert cli.main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and option[0] in err[0] and "not a dataset" in err[0], err
    assert not (tmp_path / "o").exists()
