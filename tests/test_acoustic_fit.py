"""Acoustic calibration (cassi_fit.acoustic_fit): the solver recovers a known vocal tract
from its formants, starting from the norms, away from it."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cassi_fit import acoustic_fit, tube
from cassi_fit import area_function as af
from cassi_fit.deform import default_params, deform
from cassi_fit.face_model import load_model

pytestmark = pytest.mark.slow


def test_fit_recovers_a_longer_larynx_and_narrower_pharynx():
    model = load_model()
    geometry = af.tract_geometry(model)
    p0 = default_params(model)
    opened = eqx.tree_at(lambda p: (p.jaw_translation, p.tongue), p0,
                         (jnp.array([0.0, -10.0]),
                          p0.tongue + jnp.array([[0, -10], [0, -10], [-4, -12], [-6, -10]], float)))
    frames = jax.jit(jax.vmap(lambda p: deform(model, p)))(
        jax.tree.map(lambda a, b: jnp.stack([a, b]), p0, opened))
    truth = af.TractParams(jnp.asarray(40.0), jnp.asarray(1.0), jnp.asarray(0.6), jnp.asarray(1.0))
    areas, lengths, _ = af.area_functions(geometry, frames, truth)
    measured = np.asarray(tube.formants_batch(areas, lengths).frequency)[:, :3]
    fit = acoustic_fit.fit_tract(geometry, frames, measured, 1.0)
    # the norms start 10 mm and a factor 0.6 away: their formants are off by several %
    assert np.max(fit.before) > 0.04
    assert fit.converged
    # the prior keeps the scales near the norms: within 3 %, from up to 8 %
    assert np.max(fit.after) < 0.03 and np.all(fit.after < fit.before / 2)
    assert abs(float(fit.tract.larynx_drop_mm) - 40.0) < 4.0
    record = acoustic_fit.tract_record(fit.tract)
    again = acoustic_fit.tract_from_record(record)
    assert float(again.pharynx_scale) == record["pharynx_scale"]
