"""Which phone labels are vowels (``acoustics.is_vowel``, the frames ``cassi acoustics``
scores) in every phone set real label files use: SAMPA, ARPAbet (upper and lower case,
stress digits), TIMIT and Buckeye, IPA (Montreal Forced Aligner, hand transcriptions in
TextGrids; combining marks written as ``\\u`` escapes), and the MFA TextGrid's speaker tiers
(``SPEAKER - phones``) chosen by default."""

import numpy as np
import pytest
from praatio import textgrid
from praatio.utilities.constants import Interval

from cassi_fit.acoustics import IPA_VOWEL_LETTERS, VOWELS, is_vowel
from cassi_fit.errors import MissingDataError
from cassi_fit.labels import read_textgrid

# Combining and modifier marks, by name (what the IPA labels below carry).
LONG = "\u02d0"  # ː length mark
HALF_LONG = "\u02d1"  # ˑ half-length mark
STRESS = "\u02c8"  # ˈ primary stress
STRESS2 = "\u02cc"  # ˌ secondary stress
NASAL = "\u0303"  # combining tilde: nasalised
NON_SYLLABIC = "\u032f"  # combining inverted breve below: non-syllabic (a diphthong's glide)
CENTRAL = "\u0308"  # combining diaeresis: centralised
SYLLABIC = "\u0329"  # combining vertical line below: syllabic consonant
SYLLABIC_ABOVE = "\u030d"  # combining vertical line above: syllabic (under a descender)
TIE = "\u0361"  # combining double inverted breve: tie bar
RHOTIC = "\u02de"  # ˞ rhotic hook (a modifier symbol)
ASPIRATED = "\u02b0"  # ʰ modifier letter

# Vowels the old code did not recognise (each was False before this change).
NEW_VOWELS = [
    # IPA letters beyond ASCII
    "\u0268",  # ɨ
    "\u0289",  # ʉ
    "\u026f",  # ɯ
    "\u026a",  # ɪ
    "\u028f",  # ʏ
    "\u028a",  # ʊ
    "\u00f8",  # ø
    "\u0258",  # ɘ
    "\u0275",  # ɵ
    "\u0264",  # ɤ
    "\u0259",  # ə
    "\u025b",  # ɛ
    "\u0153",  # œ
    "\u025c",  # ɜ
    "\u025e",  # ɞ
    "\u028c",  # ʌ
    "\u0254",  # ɔ
    "\u00e6",  # æ
    "\u0250",  # ɐ
    "\u0276",  # ɶ
    "\u0251",  # ɑ
    "\u0252",  # ɒ
    "\u025a",  # ɚ
    "\u025d",  # ɝ
    # IPA length, stress and diacritics
    "i" + LONG,  # iː
    "\u0251" + LONG,  # ɑː
    "\u025c" + LONG,  # ɜː (english_mfa)
    "\u025d" + LONG,  # ɝː
    "e" + HALF_LONG,  # eˑ
    STRESS + "a",  # ˈa
    STRESS2 + "\u0259",  # ˌə
    STRESS + "\u028c",  # ˈʌ
    "\u0251" + NASAL,  # ɑ̃
    "\u025b" + NASAL + LONG,  # ɛ̃ː
    "\u0250" + NON_SYLLABIC,  # ɐ̯ (german_mfa)
    "e" + CENTRAL,  # ë
    "\u00e4",  # ä precomposed: decomposes to a + diaeresis
    "\u025c" + RHOTIC,  # ɜ˞
    "\u0259" + RHOTIC,  # ə˞
    # IPA diphthongs: two vowel letters, the second may be marked non-syllabic or tied
    "a\u026a",  # aɪ
    "a\u028a",  # aʊ
    "\u0254\u026a",  # ɔɪ
    "e\u026a",  # eɪ
    "o\u028a",  # oʊ
    "\u0254\u028f",  # ɔʏ (german_mfa)
    "a\u026a" + NON_SYLLABIC,  # aɪ̯
    "a" + TIE + "\u026a",  # a͡ɪ
    "\u0259\u028a",  # əʊ
    # MFA's offglide spellings: one vowel letter + j or w
    "aj",
    "ej",
    "\u0254j",  # ɔj
    "\u0259w",  # əw (english_mfa)
    "a" + LONG + "j",  # aːj
    # TIMIT and Buckeye
    "ix",
    "ux",
    "axr",
    "ax-h",
    "IX",
    "AXR",
    "aan",  # Buckeye: nasalised vowels
    "iyn",
    # SAMPA: "2" was stripped away as a stress digit before
    "2",
    "2:",
    # X-SAMPA's rhotic diacritic
    "@`",
    # Edinburgh MRPA (MOCHA-TIMIT's labels) and Unisyn (mngu0's): long vowels, centring
    # diphthongs, r-coloured schwas
    *"ii uu oo @@ i@ e@ u@ @@r @r".split(),
]

# Vowels the old code recognised too: kept.
KEPT_VOWELS = (
    # SAMPA, long vowels included
    "a a: i: u: e: o: y: 9 3 3: 6 @ { } & Q V E I O U Y A aI aU OY eI oU @U OI "
    # ARPAbet, lower and upper case, with and without stress digits
    "aa ae ah ao aw ax ay eh er ey ih iy ow oy uh uw AA1 IY0 ER0 ER AW2 uw1 OY1 "
    # ASCII IPA letters and diphthongs (already SAMPA or plain letters)
    "i e o u y ai au ei ou aw ow"
).split()

NOT_VOWELS = [
    # consonants in every set
    *"s t p m n l r h S T N R M L HH hh ng NG sh ch jh dh th zh dx nx q bcl tcl".split(),
    *"j w J W".split(),
    "\u0294",  # ʔ
    "\u014b",  # ŋ
    "\u026b",  # ɫ
    "\u0279",  # ɹ
    "\u0283",  # ʃ
    "\u0265",  # ɥ: a glide, not in the vowel chart
    "t" + ASPIRATED,  # tʰ
    "t" + TIE + "\u0283",  # t͡ʃ
    "n" + SYLLABIC,  # n̩
    "l" + SYLLABIC,  # l̩
    "m" + SYLLABIC,  # m̩
    "\u026b" + SYLLABIC,  # ɫ̩ (english_mfa)
    "\u014b" + SYLLABIC_ABOVE,  # ŋ̍
    # syllabic consonants in ARPAbet / TIMIT: not vowels for formant scoring
    *"el em en eng EL EM EN".split(),
    # silence, noise and markers
    *"sil sp spn SIL SPN <p:> <sil> # h# pau epi : 0 1 breath".split(),
    "",
    " ",
    LONG,
    STRESS,
    NASAL,
    # three vowel letters or a vowel with two glides: not one vowel label
    "a\u026a\u0259",  # aɪə
    "ajw",
    "jw",
    "wa",  # glide first: not an MFA offglide spelling
]


@pytest.mark.parametrize("label", NEW_VOWELS, ids=ascii)
def test_newly_recognised_vowels(label):
    assert is_vowel(label)


@pytest.mark.parametrize("label", KEPT_VOWELS, ids=ascii)
def test_vowels_as_before(label):
    assert is_vowel(label)


@pytest.mark.parametrize("label", NOT_VOWELS, ids=ascii)
def test_not_vowels(label):
    assert not is_vowel(label)


def test_public_sets():
    assert {"aa", "er", "ix", "ax-h", "@", "2"} <= VOWELS
    assert not {"el", "em", "en", "r"} & VOWELS
    assert len(IPA_VOWEL_LETTERS) == 30 and "\u0259" in IPA_VOWEL_LETTERS


def _grid(path, tiers):
    grid = textgrid.Textgrid(0.0, 1.0)
    for name, labels in tiers:
        step = 1.0 / len(labels)
        entries = [Interval(k * step, (k + 1) * step, lab) for k, lab in enumerate(labels)]
        grid.addTier(textgrid.IntervalTier(name, entries, 0.0, 1.0))
    grid.save(str(path), format="long_textgrid", includeBlankSpaces=True)
    return path


def test_mfa_speaker_tiers_by_default(tmp_path):
    words, phones = ("pat",), ("p", "\u00e6", "t")
    one = _grid(tmp_path / "one.TextGrid", [("alice - words", words), ("alice - phones", phones)])
    assert read_textgrid(one).tier == "alice - phones"
    assert read_textgrid(one).labels == phones
    only_words = _grid(tmp_path / "words.TextGrid", [("x", ("a",)), ("Alice - Words", words)])
    assert read_textgrid(only_words).tier == "Alice - Words"
    # an exact "phones" tier is still first
    exact = _grid(tmp_path / "exact.TextGrid", [("alice - phones", phones), ("phones", ("a",))])
    assert read_textgrid(exact).tier == "phones"


def test_mfa_several_speakers_need_a_tier(tmp_path):
    two = _grid(
        tmp_path / "two.TextGrid",
        [
            ("alice - words", ("pat",)),
            ("alice - phones", ("p", "a", "t")),
            ("bob - words", ("ta",)),
            ("bob - phones", ("t", "a")),
        ],
    )
    with pytest.raises(
        MissingDataError, match=r"2 speakers' phones tiers \(alice - phones, bob - phones\).*tier="
    ):
        read_textgrid(two)
    assert read_textgrid(two, tier="BOB - phones").labels == ("t", "a")


def test_webmaus_phone_tier_by_default(tmp_path):
    """BAS WebMAUS's TextGrids (ORT-MAU words, KAN-MAU canonical words, MAU phones)."""
    grid = _grid(tmp_path / "maus.TextGrid",
                 [("ORT-MAU", ("Klausur",)), ("KAN-MAU", ("klaUzu:6",)), ("MAU", ("k", "aU", "u:"))])
    assert read_textgrid(grid).tier == "MAU"


def test_the_tier_is_chosen_on_the_command_line_and_for_a_dataset(tmp_path, capsys):
    """Two speakers' MFA phone tiers beside a recording: every command says in one line how
    to choose (``--tier``), and ``--tier`` (``load_recording``, ``Dataset``, a corpus item:
    ``Recording.label_tier``) makes every output use that tier."""
    import json

    from cassi_fit import cli
    from cassi_fit.corpus._items import dataset_items, load_item
    from cassi_fit.dataset import Dataset, load_recording
    from cassi_fit.labels import recording_labels
    from cassi_fit.synth import generate_corpus

    root = generate_corpus(tmp_path / "corpus", n_subjects=1, tasks="tp040")
    txy = next((root / "S01").glob("*.[Tt][Xx][Yy]"))
    length = load_recording(txy).track.length_s
    grid = textgrid.Textgrid(0.0, length)
    for name, label in [("alice - phones", "a"), ("bob - phones", "i"), ("bob - words", "he")]:
        grid.addTier(textgrid.IntervalTier(name, [Interval(0.0, length, label)], 0.0, length))
    grid.save(str(txy.with_suffix(".TextGrid")), format="long_textgrid", includeBlankSpaces=True)

    assert cli.main(["info", str(txy), "--json"]) == 0
    labels = json.loads(capsys.readouterr().out)["labels"]
    assert "2 speakers' phones tiers" in labels["used"]["error"]
    assert "--tier" in labels["used"]["error"]
    assert [t["tier"] for t in labels["beside_tiers"]] == ["alice - phones", "bob - phones",
                                                           "bob - words"]
    assert cli.main(["info", str(txy)]) == 0  # what --tier can name, in the report's line
    assert "(tiers: alice - phones (1), bob - phones (1), bob - words (1))" in (
        capsys.readouterr().out)
    assert cli.main(["info", str(txy), "--json", "--tier", "BOB - phones"]) == 0
    assert json.loads(capsys.readouterr().out)["labels"]["used"]["tier"] == "bob - phones"

    assert recording_labels(load_recording(txy, tier="bob - phones")).labels == ("i",)
    ds = Dataset(root, tier="alice - phones")
    assert recording_labels(ds.load("S01", "tp040")).labels == ("a",)
    item, = dataset_items(ds)
    assert recording_labels(load_item(item)).labels == ("a",)
    with pytest.raises(MissingDataError, match="no interval tier 'carol - phones'.*bob - words"):
        recording_labels(load_recording(txy, tier="carol - phones"))


def test_a_recording_with_nothing_to_score_says_why():
    """No labels, or labels none of which is a vowel (a words tier, an unknown phone set):
    one line naming the tier and a few of its labels, instead of '0 % scored'."""
    from cassi_fit.acoustics import unscored_line
    from cassi_fit.labels import Labels

    assert unscored_line(None).startswith("no labels")
    words = Labels([0.0, 0.5], [0.5, 1.0], ("sah", "sah"), tier="words")
    line = unscored_line(words)
    assert "2 labels of the tier 'words' (sah)" in line and "--tier" in line
    many = Labels(np.arange(10.0), np.arange(1.0, 11.0), tuple("bcdfghjklm"), tier="mau")
    assert "(b, c, d, f, g, h, j, k, ...)" in unscored_line(many)
    assert unscored_line(Labels([0.0], [1.0], ("\u0251\u02d0",), tier="phones")) is None
