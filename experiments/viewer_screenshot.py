"""The README's picture of the one-file viewer (docs/images/viewer.png): the page of the real
JW11 task 5 (``cassi_fit.view``), opened from its ``file://`` URL in headless Chromium with
the network blocked (``cassi_fit.viewer._browser``, the machinery of tests/test_viewer.py),
at a data line in the ``inside`` preset.

    python experiments/viewer_screenshot.py [RECORDING] [--out docs/images/viewer.png]

RECORDING defaults to ../shared/data/xrmb_jw11/jw11_tp005.txy beside the checkout (one
recording of one speaker), else the synthetic corpus's S01 TP040.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from shared_data import JW11_TASK5, XRMB_JW11, real_file

ROOT = Path(__file__).resolve().parents[1]


def default_recording() -> Path:
    real = real_file(XRMB_JW11, JW11_TASK5)  # ../shared beside the checkout, or above
    if real is not None:
        return real
    from cassi_fit import synth

    return synth.ensure_default_corpus() / "S01" / "TP040.TXY"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording", nargs="?", default=None)
    parser.add_argument("--out", default=str(ROOT / "docs/images/viewer.png"))
    parser.add_argument("--line", type=int, default=None,
                        help="the frame shown (default: where the jaw is most open)")
    parser.add_argument("--preset", default="inside")
    parser.add_argument("--docs", default=str(ROOT / "docs/generated"),
                        help="where the page's size table goes (viewer_page.md)")
    args = parser.parse_args(argv)

    import numpy as np

    from cassi_fit.pipeline import run_recording
    from cassi_fit.viewer import view
    from cassi_fit.viewer._browser import screenshot

    recording = Path(args.recording) if args.recording else default_recording()
    from cassi_fit.dataset import load_recording

    run = run_recording(load_recording(recording), stride=1)
    frame = args.line
    if frame is None:
        frame = int(np.argmax(np.asarray(run.animation.params.jaw_theta)))
    page = view(run)
    with tempfile.TemporaryDirectory() as tmp:
        path = page.save(Path(tmp) / "page.html")
        screenshot(path, args.out, frame=frame, preset=args.preset, size=(1200, 780))
    _size_table(page, run, recording, Path(args.docs))
    print(f"wrote {args.out} ({recording.name}, frame {frame + 1} of {run.animation.n_frames})")
    return 0


def _size_table(page, run, recording: Path, docs: Path) -> None:
    """docs/generated/viewer_page.md: what the page of this recording holds and weighs."""
    from cassi_fit.tables import markdown_text

    times = run.animation.times
    row = {"recording": recording.name, "seconds": float(times[-1] - times[0]),
           "frames": page.meta["frames"], "page_MB": page.size_bytes / 1e6,
           "components": page.meta["components"],
           "moving_vertices": page.meta["moving_vertices"],
           "max_error_mm": page.meta["max_error_mm"]}
    text = ("<!-- written by experiments/viewer_screenshot.py (make pictures) -->\n"
            "The one-file viewer's page (`experiments/viewer_screenshot.py`): one recording "
            "of one speaker, with its sound.\n\n" + markdown_text([row], digits=3))
    docs.mkdir(parents=True, exist_ok=True)
    (docs / "viewer_page.md").write_text(text)


if __name__ == "__main__":
    raise SystemExit(main())
