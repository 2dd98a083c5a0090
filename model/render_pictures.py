"""Render the face model's pictures: neutral and open jaw, front/side/inside/top views and
the midsagittal section.

    python model/render_pictures.py --out model/pictures

Writes ``neutral.png`` and ``jaw_open.png`` (the five views in a 3x2 grid) and one PNG
per view (``neutral_front.png`` ... ``neutral_midsagittal.png``), with the shared
``cassi_fit.render.Renderer``. The model alone has no subject, so the midsagittal view
shows no PAL.DAT or PHA.DAT trace and no pellets.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

JAW_OPEN_RAD = 0.25  # about 14 degrees about the model's condyle


def poses(model):
    """name -> vertices (V, 3) for the pictures."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from cassi_fit import rigid
    from cassi_fit.deform import default_params, deform

    pivot = jnp.array([model.measures["jaw_pivot_x"], model.measures["jaw_pivot_y"]])
    theta, t = rigid.from_pivot(jnp.asarray(JAW_OPEN_RAD), pivot)
    p = eqx.tree_at(lambda q: (q.jaw_theta, q.jaw_translation), default_params(model), (theta, t))
    return {"neutral": np.asarray(model.vertices), "jaw_open": np.asarray(deform(model, p))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "pictures"))
    ap.add_argument("--size", type=int, default=1000, help="grid image width = height (px)")
    args = ap.parse_args(argv)
    from cassi_fit.face_model import load_model
    from cassi_fit.render import VIEWS, Renderer, save_png

    model = load_model()
    out = Path(args.out)
    captions = {"neutral": "neutral face", "jaw_open": f"jaw open {JAW_OPEN_RAD} rad (CASSI weights)"}
    with Renderer(model, size=(args.size, args.size * 2 // 3), views=VIEWS, antialias=4) as grid:
        for name, verts in poses(model).items():
            save_png(out / f"{name}.png", grid.render(verts, caption=captions[name]))
    with Renderer(model, size=(args.size // 2, args.size // 2), views=VIEWS, grid=False,
                  antialias=4) as single:
        for name, verts in poses(model).items():
            for view, image in single.render_views(verts).items():
                save_png(out / f"{name}_{view}.png", image)
    print(f"pictures written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
