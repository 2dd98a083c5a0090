"""One recording in one self-contained web page: the animated face, its sound, its labels.

``cassi view RECORDING --out talk.html`` and :func:`view` (shown inline in Jupyter) write
one HTML file that opens offline from a ``file://`` URL with nothing to install: the face
(every data line a frame, :mod:`~cassi_fit.viewer._encode`'s compact encoding), the
measured pellets with trails and the model's pellet sites, the paper's four views as camera
presets with orbit and zoom, part toggles, the midsagittal section, the label timeline, the
jaw opening and lip aperture plots and the recording's sound (slowed with the picture).

By concern: ``_encode`` (the frames, PCA-compressed and quantised), ``_data`` (what the
page holds), ``_page`` (the HTML, :class:`ViewerPage`, :func:`view`, :func:`write_view`),
``_browser`` (headless Chromium through Playwright, for the tests and the README's
screenshot). The page's script is ``assets/viewer.js``, built from ``viewer_js/`` (three.js
pinned by npm, bundled by esbuild; its licence is ``assets/THREE_LICENSE``).
"""

from __future__ import annotations

from ._encode import decode_motion as decode_motion
from ._encode import encode_motion as encode_motion
from ._page import ViewerPage as ViewerPage
from ._page import view as view
from ._page import write_view as write_view

__all__ = ["ViewerPage", "decode_motion", "encode_motion", "view", "write_view"]
