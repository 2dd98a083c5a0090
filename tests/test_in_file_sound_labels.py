"""Sound and labels stored inside a recording file (issue 28 part 3): mview's ``AUDIO`` and
``WORDS``/``PHONES``, an EMU bundle's media and levels, reach the video and the jaw tables
exactly as a ``.wav`` and a ``.lab`` beside the file would."""

import os
import types
import warnings
import wave

import numpy as np
import pytest

from cassi_fit import recording_video
from cassi_fit.corpus import CorpusItem
from cassi_fit.dataset import DefaultHeadMeasuresWarning, load_recording
from cassi_fit.ema.mview import read_mview, write_mview
from cassi_fit.ema.synthetic import write_ema_corpus
from cassi_fit.errors import DataFormatError
from cassi_fit.labels import Labels, recording_labels, write_lab
from cassi_fit.sound import Sound, check_sound


def _quiet(load, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load(*args, **kw)


def _wav_samples(path):
    with wave.open(str(path), "rb") as w:
        return w.getframerate(), np.frombuffer(w.readframes(w.getnframes()), "<i2")


@pytest.fixture(scope="module")
def mview_folder(tmp_path_factory):
    """A synthetic mview subject whose ``.mat`` holds the sound and two label tiers, with no
    ``.wav`` or ``.lab`` beside it."""
    root = write_ema_corpus(tmp_path_factory.mktemp("mv") / "corpus", format="mview",
                            n_subjects=1, tasks="tp040", seed=2)
    folder = root / "S01"
    mat, wav = folder / "tp040.mat", folder / "tp040.wav"
    raw = read_mview(mat)
    rate, samples = _wav_samples(wav)
    length = raw.times[-1]
    words = Labels([0.2, 1.0], [1.0, length - 0.2], ["she", "had"], "words")
    phones = Labels([0.2, 0.5, 1.0], [0.5, 1.0, length - 0.2], ["sh", "iy", "hh"], "phones")
    new = write_mview(folder / "new.mat", raw, variable="tp040",
                      audio=(samples / 32768.0, float(rate)), labels=[words, phones])
    os.replace(new, mat)  # the reader registered tp040.mat as an input: never overwritten
    original = wav.read_bytes()
    wav.unlink()
    return folder, original


def test_mview_sound_and_labels_are_the_recordings(mview_folder):
    folder, original = mview_folder
    rec = _quiet(load_recording, folder / "tp040.mat")
    assert rec.audio is None and rec.sound.kind == "mview AUDIO"
    with rec.sound.wav_file() as path:
        got = _wav_samples(path)
    with open(folder / "x.wav", "wb") as fh:
        fh.write(original)
    want = _wav_samples(folder / "x.wav")
    (folder / "x.wav").unlink()
    assert got[0] == want[0] and np.array_equal(got[1], want[1])
    assert [t.tier for t in rec.labels] == ["words", "phones"]
    chosen = recording_labels(rec)
    assert chosen.tier == "phones" and chosen.labels == ("sh", "iy", "hh")
    assert recording_labels(rec, tier="WORDS").labels == ("she", "had")


def test_a_lab_beside_the_file_wins_over_the_one_inside(mview_folder, tmp_path):
    folder, _ = mview_folder
    lab = folder / "tp040.lab"
    write_lab(lab, Labels([0.1], [0.9], ["beside"]))
    try:
        rec = _quiet(load_recording, folder / "tp040.mat")
        assert recording_labels(rec).labels == ("beside",)
    finally:
        lab.unlink()


def test_the_video_gets_the_sound_and_labels_inside_the_file(mview_folder, tmp_path,
                                                             monkeypatch):
    """write_recording_video is the one place that asks the recording for its sound and
    labels: the MP4 writer receives a .wav holding the file's AUDIO and the phone tier."""
    folder, original = mview_folder
    rec = _quiet(load_recording, folder / "tp040.mat")
    seen = {}

    def fake_write_animation(path, animation, renderer, *, audio, labels, **kw):
        seen["audio"] = None if audio is None else _wav_samples(audio)
        seen["labels"] = labels
        return path

    monkeypatch.setattr(recording_video, "write_animation", fake_write_animation)
    renderer = types.SimpleNamespace(set_traces=lambda traces: None)
    run = types.SimpleNamespace(recording=rec, state=types.SimpleNamespace(scale=1.0),
                                animation=None)
    recording_video.write_recording_video(tmp_path / "v.mp4", run, renderer=renderer)
    rate, samples = seen["audio"]
    assert rate == 16000 and samples.size > 0.9 * rec.track.times[-1] * rate
    assert seen["labels"].labels == ("sh", "iy", "hh")
    recording_video.write_recording_video(tmp_path / "v.gif", run, renderer=renderer)
    assert seen["audio"] is None  # a GIF has no sound


def test_the_jaw_table_has_the_labels_inside_the_file(mview_folder, tmp_path):
    from cassi_fit.jaw_table import jaw_spec, jaw_task

    folder, _ = mview_folder
    item = CorpusItem("S01", "tp040", str(folder / "tp040.mat"))
    spec = jaw_spec(jaw="coupled-rotation", jaw_sensors="MNI")
    result = jaw_task(item, str(tmp_path), spec=spec)
    frames = (tmp_path / "S01" / "tp040.jaw.csv").read_text().splitlines()
    column = frames[0].split(",").index("label")
    assert {line.split(",")[column] for line in frames[1:]} >= {"sh", "iy", "hh"}
    segments = (tmp_path / "S01" / "tp040.segments.csv").read_text().splitlines()
    assert [s.split(",")[0] for s in segments[1:]] == ["sh", "iy", "hh"]
    assert result.row["label_file"] == "tp040.mat"


def test_emu_sound_inside_reaches_the_video(tmp_path, monkeypatch):
    root = write_ema_corpus(tmp_path / "db", format="emu", n_subjects=1, tasks="tp040", seed=4)
    rec = _quiet(load_recording, root / "S01_ses" / "tp040_bndl")
    seen = {}
    monkeypatch.setattr(recording_video, "write_animation",
                        lambda path, *a, audio, labels, **kw: seen.update(
                            audio=audio and _wav_samples(audio), labels=labels))
    run = types.SimpleNamespace(recording=rec, state=types.SimpleNamespace(scale=1.0),
                                animation=None)
    recording_video.write_recording_video(tmp_path / "v.mp4", run,
                                          renderer=types.SimpleNamespace(set_traces=print))
    assert seen["audio"][0] == 16000 and seen["labels"].tier == "Segment"


def test_sound_held_in_memory_is_checked_like_a_file():
    sound = Sound.from_samples(np.zeros(8000), 16000, "x.mat: AUDIO", "mview AUDIO")
    with pytest.raises(DataFormatError, match=r"x\.mat: AUDIO"):
        check_sound(sound, 5.0)  # 0.5 s of sound for 5 s of pellets
    assert check_sound(sound, 0.5).status == "ok"
