"""The computation tests/test_float32.py runs twice, in float32 (a fresh process with x64
off) and in float64 (the test process): in whatever precision JAX is set to, return plain
arrays to compare.

- ``vertices``, ``pellets_model``: the sentence of synthetic subject S01 initialized and
  animated every 12th line (improved mode) with the fixed-pivot jaw fit;
- ``gradient``: d(a fixed weighting of every vertex)/d(the face parameters) at a posed
  face, all parameters flattened.
"""

from __future__ import annotations

from pathlib import Path

STRIDE = 12


def case() -> dict:
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    import zoo

    from cassi_fit.dataset import Recording
    from cassi_fit.deform import default_params, deform
    from cassi_fit.pipeline import run_recording

    anatomy = zoo.subject(0)
    track, _ = zoo.recording("tp040", 0, clean=True)
    recording = Recording(subject=anatomy.name, task="tp040", track=track,
                          palate=anatomy.palate, pharynx=anatomy.pharynx, head=anatomy.head,
                          head_is_default=False, audio=None,
                          path=Path(f"/data/{anatomy.name}/tp040.txy"))
    run = run_recording(recording, stride=STRIDE, jaw="fixed-pivot")
    animation = run.animation

    model = run.state.model
    params = default_params(model)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=np.shape(model.vertices)),
                          jnp.asarray(model.vertices).dtype)

    def weighted(p):
        return jnp.sum(weights * deform(model, p))

    posed = eqx.tree_at(lambda p: (p.jaw_theta, p.tongue, p.upper_lip), params,
                        (params.jaw_theta + 0.1, params.tongue + 1.0, params.upper_lip + 0.5))
    gradient = jax.jit(jax.grad(weighted))(posed)
    flat = jnp.concatenate([jnp.ravel(leaf) for leaf in jax.tree.leaves(gradient)])
    return {"vertices": animation.vertices, "pellets_model": animation.pellets_model,
            "gradient": flat}
