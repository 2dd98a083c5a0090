"""Render the face at 1024 px from the front, the side and three-quarters, at rest and
with the jaw open (the pictures of model/README.md's face section).

    python model/render_face.py --out model/pictures

Writes ``face_{neutral,jaw_open}_{front,side,three_quarter}.png``. The renderer's views
are the paper's (front, side, inside, top); the three-quarter picture is its front view of
the mesh turned 35 degrees about the vertical axis (the subject's right side toward the
camera), with each eye's iris and pupil coloured from the unturned rest mesh.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

TURN_DEG = 35.0


def turned(vertices: np.ndarray, degrees: float = TURN_DEG) -> np.ndarray:
    """The vertices turned about the vertical (y) axis: +degrees brings the subject's right
    (-z) toward a camera in front (+x)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    x, z = vertices[:, 0], vertices[:, 2]
    return np.column_stack([c * x - s * z, vertices[:, 1], s * x + c * z])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "pictures"))
    ap.add_argument("--size", type=int, default=1024, help="image width = height (px)")
    args = ap.parse_args(argv)
    import equinox as eqx
    import jax.numpy as jnp
    from render_pictures import poses

    from cassi_fit.face_model import MATERIALS, load_model
    from cassi_fit.render import Renderer, save_png
    from cassi_fit.render._pieces import _iris_factors

    model = load_model()
    out = Path(args.out)
    size = (args.size, args.size)
    shots = poses(model)
    with Renderer(model, size=size, views=("front", "side"), grid=False, antialias=4) as r:
        for name, verts in shots.items():
            for view, image in r.render_views(verts).items():
                save_png(out / f"face_{name}_{view}.png", image)
    rest = np.asarray(model.vertices)
    model_t = eqx.tree_at(lambda m: m.vertices, model, jnp.asarray(turned(rest)))
    with Renderer(model_t, size=size, views=("front",), grid=False, antialias=4) as r:
        eye = MATERIALS.index("eye")
        iris = _iris_factors(rest, np.asarray(model.faces), np.asarray(model.face_material), eye)
        for piece in r._pieces:  # iris and pupil from the unturned eyes
            if piece.material == "eye" and iris is not None:
                piece.buffer[:, 6:] = iris[piece.vertex_index]
        for name, verts in shots.items():
            image = r.render_views(turned(verts))["front"]
            save_png(out / f"face_{name}_three_quarter.png", image)
    print(f"face pictures written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
