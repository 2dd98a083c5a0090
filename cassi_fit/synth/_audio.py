"""Stage 4 of the synthetic corpus, audio: a voiced buzz whose loudness and formants follow
the articulators' control curves, as a 16 kHz ``.wav`` aligned with the pellet frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from jaxtyping import Float, Int

from ._kinematics import FRAME_STEP_S
from ._tasks import CONTROLS

AUDIO_RATE_HZ = 16000


def synth_audio(
    controls: Float[np.ndarray, "n c"], times: Float[np.ndarray, " n"], f0_hz: float,
    rng: np.random.Generator,
) -> Int[np.ndarray, " samples"]:
    """A voiced buzz that follows the articulators: ``(n_samples,)`` int16 at 16 kHz.

    ``controls`` ``(n, len(CONTROLS))`` on the frame times ``times`` (s). Sample ``k`` is at
    ``k / 16000`` s, so the audio starts with the recording (time 0) and lasts as long
    (``n * 6866`` us). Loudness follows voicing and the mouth opening (silent in a lip
    or tongue-tip closure); the first two formants follow jaw opening and tongue body
    position. It is a harmonic sum, not speech, but its envelope is aligned to the
    movements, which is what a speech-sync demo needs.
    """
    c = {name: controls[:, i] for i, name in enumerate(CONTROLS)}
    n_samples = int(round(times.shape[0] * FRAME_STEP_S * AUDIO_RATE_HZ))
    t = np.arange(n_samples) / AUDIO_RATE_HZ
    # Linear interpolation from frames to samples, shared by every curve below.
    pos = np.clip((t - times[0]) / FRAME_STEP_S, 0.0, times.shape[0] - 1.0)
    i0 = np.minimum(pos.astype(np.int64), times.shape[0] - 2)
    w = pos - i0

    def at_samples(curve):
        return curve[i0] * (1.0 - w) + curve[i0 + 1] * w

    closure = np.clip(np.maximum(c["lip_close"], c["tip_up"] - 0.2), 0.0, 1.0)
    opening = (1.0 - closure) * (0.35 + 0.65 * np.clip(c["jaw_deg"] / 8.0, 0.0, 1.0))
    loud = at_samples(np.clip(c["voicing"], 0.0, 1.0) * opening)
    f1 = 300.0 + 55.0 * c["jaw_deg"] - 8.0 * c["body_up"]  # per frame, Hz
    f2 = 1450.0 + 70.0 * c["body_fwd"] + 25.0 * c["body_up"] - 250.0 * c["lip_round"]
    f0 = f0_hz * (1.05 - 0.1 * t / max(t[-1], 1e-9)) * (1.0 + 0.02 * np.sin(2 * np.pi * 4.0 * t))
    base = np.exp(1j * (2 * np.pi * np.cumsum(f0) / AUDIO_RATE_HZ))
    harmonic = base.copy()  # exp(i k phase), by repeated multiplication (cheaper than sin)
    signal = np.zeros(n_samples)
    # Harmonic gains change at the articulators' pace: computed per frame, interpolated.
    for k in range(1, int(3800.0 // f0_hz) + 1):
        fk = k * f0_hz
        gain = (
            np.exp(-0.5 * ((fk - f1) / 120.0) ** 2)
            + 0.6 * np.exp(-0.5 * ((fk - f2) / 180.0) ** 2)
            + 0.25 * np.exp(-0.5 * ((fk - 2700.0) / 250.0) ** 2)
            + 0.3 / k
        )
        signal += at_samples(gain) * harmonic.imag
        harmonic *= base
    hiss = np.diff(rng.normal(size=n_samples + 1)) * at_samples(c["frication"]) * 0.15
    signal = signal * loud + hiss
    peak = np.max(np.abs(signal))
    scale = 0.6 * 32767 / peak if peak > 0 else 0.0
    return np.round(signal * scale).astype(np.int16)


def _write_wav(path: Path, samples: np.ndarray, *, overwrite: bool) -> Path:
    """16 kHz mono int16 ``.wav`` (stdlib ``wave``), written atomically."""
    import wave

    from .._io import atomic_write

    def write(fh):
        with wave.open(fh, "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(AUDIO_RATE_HZ)
            w.writeframes(samples.astype("<i2").tobytes())

    return atomic_write(path, write, overwrite=overwrite, binary=True, data_file=True)
