"""The tongue as an organ: a closed tube down to the hyoid, hung from the jaw, volume kept.

Sources of the ranges: docs/TONGUE.md (Liegeois et al. 2010 for the rest volume).
"""

import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import zoo

from cassi_fit import deform as deform_module
from cassi_fit import rigid
from cassi_fit.dataset import Recording
from cassi_fit.deform import default_params, deform, tongue_midline
from cassi_fit.face_model import load_model
from cassi_fit.pipeline import run_recording
from cassi_fit.synth import TASKS
from cassi_fit.tongue import closed_mesh_volume, tongue_faces, tongue_volume, tongue_volumes

MODEL = load_model()
L = MODEL.landmarks
REST = np.asarray(MODEL.vertices)
PIVOT = jnp.array([MODEL.measures["jaw_pivot_x"], MODEL.measures["jaw_pivot_y"]])
REST_ML = float(tongue_volume(MODEL, REST))
DEFORM = jax.jit(lambda p: deform(MODEL, p))
# Liegeois, Albert & Limme 2010 (MRI, 70 adults aged 20-37): 68.9 +- 7.0 mL (women),
# 89.9 +- 11.5 mL (men); the adult range here: women's mean - 2 SD .. men's mean + 2 SD.
ADULT_ML = (68.9 - 2 * 7.0, 89.9 + 2 * 11.5)
FRAMES = 60  # frames per task (strides of about 6 to 32 lines)


def with_(**kw):
    p = default_params(MODEL)
    names = tuple(kw)
    return eqx.tree_at(lambda q: tuple(getattr(q, n) for n in names), p,
                       tuple(jnp.asarray(kw[n], dtype=float) for n in names))


def jaw_open(rad=0.25):
    theta, t = rigid.from_pivot(rad, PIVOT)
    return {"jaw_theta": theta, "jaw_translation": t}


def test_the_tongue_is_a_closed_outward_tube_of_adult_volume():
    faces = tongue_faces(MODEL)
    edges = {}
    for a, b, c in faces:
        for e in ((a, b), (b, c), (c, a)):
            edges[e] = edges.get(e, 0) + 1
    # closed and consistently oriented: every edge once in each direction
    assert all(n == 1 and edges.get((b, a)) == 1 for (a, b), n in edges.items())
    assert ADULT_ML[0] < REST_ML < ADULT_ML[1]
    # the volume does not depend on where the origin is (closed mesh)
    shifted = closed_mesh_volume(jnp.asarray(REST) + jnp.array([[40.0, -7.0, 3.0]]), faces)
    assert float(shifted) / 1000 == pytest.approx(REST_ML, rel=1e-9)


def test_the_root_reaches_down_to_the_hyoid_region():
    tongue = REST[MODEL.regions["tongue"]]
    assert tongue[:, 1].min() < -40.0  # the hyoid sits about 45 mm below the incisal plane
    assert tongue[:, 1].min() > -55.0


def _recording(task, anatomy):
    track, _ = zoo.recording(task, 0)
    return Recording(subject=anatomy.name, task=task, track=track, palate=anatomy.palate,
                     pharynx=anatomy.pharynx, head=anatomy.head, head_is_default=False,
                     audio=None, path=Path(f"/data/{anatomy.name}/{task}.txy"))


@pytest.fixture(scope="module")
def all_tasks():
    """Every synthetic task of subject S01 through the real pipeline (improved mode), each
    with the stride that gives at most 64 frames (one compiled size for all):
    task -> (state, animation)."""
    anatomy = zoo.subject(0)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for task in TASKS:
            recording = _recording(task, anatomy)
            stride = -(-recording.track.times.shape[0] // FRAMES)
            out[task] = run_recording(recording, stride=stride)[2:4]
    return out


def test_volume_is_kept_within_3_percent_on_every_synthetic_task(all_tasks):
    for task, (state, animation) in all_tasks.items():
        ml = tongue_volumes(state.model, animation.vertices)
        assert ml.shape == (animation.n_frames,) and animation.n_frames > 20
        assert np.all(np.abs(ml / REST_ML - 1.0) < 0.03), (task, ml.min(), ml.max())


def test_without_volume_preservation_the_tasks_change_the_volume(all_tasks, monkeypatch):
    """The guard of the test above: with the width scaling removed from the tongue stage,
    the same frames' tongue leaves the +-3 % band."""
    state = all_tasks["tp040"][0]
    style = {"tongue_anchor": state.tongue_anchor, "jaw_weights": state.jaw_weights}
    frames = jax.tree.map(lambda *x: jnp.concatenate([a[::3] for a in x]),
                          *[a.params for _, a in all_tasks.values()])
    monkeypatch.setattr(deform_module, "keep_volume", lambda model, v, volume: v)
    verts = jax.jit(jax.vmap(lambda p: deform(state.model, p, **style)))(frames)
    ml = tongue_volumes(state.model, verts)
    assert np.abs(ml / REST_ML - 1.0).max() > 0.03


def test_the_tongue_hangs_from_the_jaw():
    """Opening the jaw with the tongue params fixed carries the floor of the mouth down
    with the lower teeth; the pellet sites stay exactly at rest + params."""
    d = np.array([[1.0, -2.0], [0.5, 1.0], [-1.0, 2.0], [2.0, -1.0]])
    closed = np.asarray(DEFORM(with_(tongue=d)))
    opened = np.asarray(DEFORM(with_(tongue=d, **jaw_open())))
    for k, name in enumerate(("T1", "T2", "T3", "T4")):
        np.testing.assert_allclose(opened[L[name], :2] - REST[L[name], :2], d[k], atol=1e-9)
    idx, _ = tongue_midline(MODEL)
    ring = (L["T2"] - L["T1"]) // 4
    floor = idx[:-2].reshape(-1, ring)[:, ring // 2]  # lower midline of every section
    carried_by = np.asarray(MODEL.fields["tongue_jaw"])  # the share of the jaw's motion
    genial = floor[np.argmax(carried_by[floor])]
    assert carried_by[genial] == 1.0
    incisor = L["lower_incisor_tip"]
    drop_teeth = closed[incisor, 1] - opened[incisor, 1]
    assert drop_teeth > 10.0
    motion = (jaw_open()["jaw_theta"], jaw_open()["jaw_translation"])
    share = float(MODEL.jaw_weights["cassi"][incisor])  # the mandible's own (1 with CASSI's)

    def riding(i):  # where the jaw alone carries vertex i (its share of the mandible's motion)
        return np.asarray(rigid.apply(*rigid.fractional(motion, carried_by[i] * share),
                                      REST[i, :2]))

    sites = [L[name] for name in ("T1", "T2", "T3", "T4")]
    # pellets that move just as the jaw carries their sites leave nothing to spread along
    # the tongue: the floor at the genial attachment moves exactly with the mandible
    with_the_jaw = np.stack([riding(i) - REST[i, :2] for i in sites])
    still = np.asarray(DEFORM(with_(tongue=with_the_jaw, **jaw_open())))
    np.testing.assert_allclose(still[genial, :2], riding(genial), atol=1e-9)
    # with the pellets held (d both times), the floor moves with the mandible less its
    # small follow weight times the pellets' motion relative to the jaw, spread along the
    # tongue to the attachment (the stage's rule: carried + follow * spread)
    from cassi_fit.tongue import tongue_displacement

    arc = np.asarray(MODEL.fields["tongue_s"])
    spread = np.asarray(tongue_displacement(arc[genial][None], arc[sites], with_the_jaw,
                                            MODEL.measures["tongue_anchor_s"]))[0]
    follow = float(MODEL.fields["tongue_follow"][genial])
    assert follow < 0.5 and np.linalg.norm(follow * spread) > 0.5  # a visible part
    moved = opened[genial, :2] - closed[genial, :2]
    np.testing.assert_allclose(moved, riding(genial) - REST[genial, :2] - follow * spread,
                               atol=1e-9)
    # the whole floor goes down, the front most, the hyoid end least
    drops = closed[floor, 1] - opened[floor, 1]
    assert np.all(drops > 0.2 * drop_teeth) and drops.max() > 0.7 * drop_teeth
    assert drops[-1] < 0.5 * drops.max()


def test_the_width_pays_for_the_volume_and_gradients_are_finite():
    """Raising the dorsum stretches the tongue: the width narrows (the sites at z = 0 stay),
    and the volume step is differentiable."""
    lateral = int(np.argmax(REST[:, 2] * np.isin(np.arange(len(REST)), MODEL.regions["tongue"])))
    up = np.tile([0.0, 6.0], (4, 1))
    out = np.asarray(DEFORM(with_(tongue=up)))
    assert out[lateral, 2] < REST[lateral, 2] - 0.5
    assert float(tongue_volume(MODEL, out)) == pytest.approx(REST_ML, rel=1e-9)

    def width(tongue):
        return DEFORM(with_(tongue=tongue, **jaw_open(0.1)))[lateral, 2]

    g = np.asarray(jax.grad(width)(jnp.asarray(up)))
    assert np.all(np.isfinite(g)) and np.abs(g).max() > 1e-3


def test_cassi_flat_tongue_keeps_the_papers_behaviour():
    """CASSI mode: the flat sheet is moved by the pellets only (no jaw attachment, no
    volume to keep)."""
    flat = jax.jit(lambda p: deform(MODEL, p, tongue_shape="flat", tongue_anchor="fixed"))
    closed, opened = np.asarray(flat(default_params(MODEL))), np.asarray(flat(with_(**jaw_open())))
    idx = MODEL.regions["tongue"]
    np.testing.assert_array_equal(opened[idx], closed[idx])
    assert abs(float(tongue_volume(MODEL, closed))) < 1e-6 * REST_ML
