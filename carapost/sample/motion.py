"""What changes from frame to frame: expressions, gaze, head slip, camera-bar flex, lighting.

All tracks are smooth functions of time drawn from a seeded generator.  Every
take opens the same way so that even a dozen frames show what the tests need:
frame 0 is a neutral face (the seeds are clicked on it), the upper lip curls
from frame 1 to 7 and holds, and both eyes blink, closed on frames 6 to 8.
After that come speech-like jaw motion with one wide opening, blinks every
1-4 s, and every slower expression at least once (more in long takes), at
random times.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from .face import EXPRESSIONS

__all__ = ["Motion", "make_motion", "smooth_noise"]

_K = {n: i for i, n in enumerate(EXPRESSIONS)}


@dataclass
class Motion:
    """Per-frame tracks of a take (F frames).

    Attributes
    ----------
    weights : ndarray, shape (F, len(EXPRESSIONS))
        Expression weights, 0..1.
    gaze : ndarray, shape (F, 2)
        Iris offset on the eye (mm, image right and down).
    head_R, head_t : ndarray, shapes (F, 3, 3), (F, 3)
        Head slip: rig point = ``head_R (p - HEAD_PIVOT) + HEAD_PIVOT + head_t``.
    bar_R, bar_t : ndarray, shapes (F, 3, 3), (F, 3)
        Flex of the whole camera bar about the camera centroid (rig frame).
    caddy_R, caddy_t : ndarray, shapes (F, 2, 3, 3), (F, 2, 3)
        Much smaller independent motion of each caddy (left, right).
    gain : ndarray, shape (F, 4)
        Per-camera exposure gain (LED and auto-exposure variation).
    """

    weights: np.ndarray
    gaze: np.ndarray
    head_R: np.ndarray
    head_t: np.ndarray
    bar_R: np.ndarray
    bar_t: np.ndarray
    caddy_R: np.ndarray
    caddy_t: np.ndarray
    gain: np.ndarray


#: The head slips about a point near the middle of the head (rig mm).
HEAD_PIVOT = np.array([0.0, -20.0, 85.0])


def smooth_noise(rng: np.random.Generator, frames: int, dims: int, sigma_frames: float) -> np.ndarray:
    """Gaussian-filtered white noise with unit standard deviation per sample, shape (frames, dims)."""
    pad = int(4 * sigma_frames) + 1
    w = rng.standard_normal((frames + 2 * pad, dims))
    out = gaussian_filter1d(w, sigma_frames, axis=0, mode="reflect")[pad:pad + frames]
    # Variance of unit white noise after a normalised Gaussian kernel of std s: 1 / (2 s sqrt(pi)).
    return out * np.sqrt(2.0 * sigma_frames * np.sqrt(np.pi))


def _pulse(frames: int, start: float, attack: float, hold: float, release: float) -> np.ndarray:
    """0..1 pulse: raised-cosine rise over ``attack`` frames, ``hold``, raised-cosine fall."""
    t = np.arange(frames, dtype=np.float64)
    up = np.clip((t - start) / max(attack, 1e-6), 0.0, 1.0)
    down = np.clip((t - start - attack - hold) / max(release, 1e-6), 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * up) - (0.5 - 0.5 * np.cos(np.pi * down))


def _put(track: np.ndarray, pulse: np.ndarray, amp: float) -> None:
    np.maximum(track, amp * pulse, out=track)


def _expressions(rng: np.random.Generator, frames: int, rate: float) -> np.ndarray:
    w = np.zeros((frames, len(EXPRESSIONS)))
    s = rate / 60.0        # the scripted opening is in 60 fps frames
    # The opening: lip curl from frame 1 to 7, held to 11; a blink closed at frames 6-8.
    _put(w[:, _K["lip_curl"]], _pulse(frames, 1.0 * s, 6.0 * s, 5.0 * s, 9.0 * s), 1.0)
    blink = _pulse(frames, 3.0 * s, 3.0 * s, 2.5 * s, 4.5 * s)
    _put(w[:, _K["blink_L"]], blink, 1.0)
    _put(w[:, _K["blink_R"]], blink, 1.0)
    t0 = 16.0 * s
    span = max(frames - t0 - 0.15 * rate, 1.0)          # room for events after the opening
    # Speech: bursts of syllables (fast jaw motion), with pauses, and one wide "ah"
    # somewhere in every take (then more, at random).
    ah = t0 + rng.uniform(0.0, 0.6) * span
    _put(w[:, _K["jaw_open"]], _pulse(frames, ah, 0.08 * rate, rng.uniform(0.2, 0.4) * rate, 0.12 * rate),
         rng.uniform(0.9, 1.0))
    t = t0 + rng.uniform(0, 10) * s
    while t < frames:
        if abs(t - ah) < 0.6 * rate:
            t += 0.3 * rate
            continue
        if rng.random() < 0.15:
            dur = rng.uniform(0.35, 0.7) * rate
            _put(w[:, _K["jaw_open"]], _pulse(frames, t, 0.08 * rate, dur, 0.12 * rate), rng.uniform(0.85, 1.0))
            t += dur + 0.2 * rate
        else:
            for _ in range(int(rng.integers(2, 7))):
                a = rng.uniform(0.05, 0.12) * rate
                _put(w[:, _K["jaw_open"]], _pulse(frames, t, a, rng.uniform(0, 0.04) * rate, a),
                     rng.uniform(0.2, 0.75))
                t += 2 * a + rng.uniform(0.0, 0.05) * rate
        t += rng.uniform(0.15, 0.8) * rate
    # Blinks every 1-4 s (sometimes a wink).
    t = t0 + rng.uniform(0.3, 1.5) * rate
    while t < frames:
        p = _pulse(frames, t, rng.uniform(0.05, 0.08) * rate, rng.uniform(0.02, 0.06) * rate,
                   rng.uniform(0.1, 0.15) * rate)
        r = rng.random()
        if r > 0.1:
            _put(w[:, _K["blink_L"]], p, 1.0)
        if r < 0.1 or r > 0.2:
            _put(w[:, _K["blink_R"]], p, 1.0)
        t += rng.uniform(1.0, 4.0) * rate
    # Slower expressions: each at least once in every take (at a random time),
    # more in long takes: smiles and brow raises mostly on both sides.
    for name, per_s in (("smile", 0.25), ("brow_raise", 0.2), ("brow_furrow", 0.1), ("lip_curl", 0.08),
                        ("pucker", 0.1), ("cheek_puff", 0.05)):
        n = 1 + rng.poisson(per_s * span / rate)
        for _ in range(n):
            start = t0 + rng.uniform(0.0, 0.85) * span
            p = _pulse(frames, start, rng.uniform(0.12, 0.3) * rate, rng.uniform(0.1, 0.8) * rate,
                       rng.uniform(0.15, 0.4) * rate)
            amp = rng.uniform(0.5, 1.0)
            if name in ("smile", "brow_raise"):
                _put(w[:, _K[name + "_L"]], p, amp * rng.uniform(0.75, 1.0))
                _put(w[:, _K[name + "_R"]], p, amp * rng.uniform(0.75, 1.0))
            else:
                _put(w[:, _K[name]], p, amp)
    w[0] = 0.0
    return np.clip(w, 0.0, 1.0)


def _gaze(rng: np.random.Generator, frames: int, rate: float) -> np.ndarray:
    """Fixations with quick saccades between them (mm on the eye)."""
    g = np.zeros((frames, 2))
    cur = np.zeros(2)
    t = int(rng.uniform(0.2, 0.8) * rate)
    g[:] = cur
    while t < frames:
        nxt = np.array([rng.uniform(-3.0, 3.0), rng.uniform(-1.5, 1.5)])
        ramp = _pulse(frames, t, max(2.0, 0.04 * rate), 1e9, 1.0)[:, None]
        g = g * (1 - ramp) + nxt * ramp
        cur = nxt
        t += int(rng.uniform(0.3, 1.2) * rate)
    return g


def _rotations(rotvec_deg: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(rotvec_deg)).as_matrix()


def make_motion(rng: np.random.Generator, frames: int, rate: float = 60.0) -> Motion:
    """All per-frame tracks of a take.

    Parameters
    ----------
    rng : numpy.random.Generator
    frames : int
    rate : float
        Frames per second (durations are in seconds).
    """
    w = _expressions(rng, frames, rate)
    gaze = _gaze(rng, frames, rate)
    jaw = w[:, _K["jaw_open"]]
    # The chin strap moves the helmet as the jaw works: slip follows the jaw,
    # lagging (smoothed), plus slow wander.  Up to about a millimetre.
    jaw_s = gaussian_filter1d(jaw, 0.05 * rate, mode="nearest")
    head_t = 0.25 * smooth_noise(rng, frames, 3, 0.4 * rate)
    head_t[:, 1] -= 0.6 * jaw_s
    head_t[:, 2] += 0.3 * jaw_s
    head_rv = 0.12 * smooth_noise(rng, frames, 3, 0.4 * rate)
    head_rv[:, 0] += 0.35 * jaw_s
    # The camera bar rings a little after fast jaw motion (a damped ~12 Hz
    # oscillation driven by the jaw's acceleration) and wanders slowly.
    acc = np.diff(jaw, 2, prepend=jaw[:1], append=jaw[-1:]) * rate * rate / 3600.0
    kern_t = np.arange(int(0.3 * rate)) / rate
    kern = np.exp(-kern_t / 0.06) * np.sin(2 * np.pi * 12.0 * kern_t)
    ring = np.convolve(acc, kern)[:frames]
    bar_t = 0.03 * smooth_noise(rng, frames, 3, 0.3 * rate)
    bar_t[:, 1] += 0.4 * ring
    bar_rv = 0.01 * smooth_noise(rng, frames, 3, 0.3 * rate)
    bar_rv[:, 0] += 0.15 * ring
    caddy_t = 0.006 * smooth_noise(rng, frames, 6, 0.2 * rate).reshape(frames, 2, 3)
    caddy_rv = 0.002 * smooth_noise(rng, frames, 6, 0.2 * rate).reshape(frames, 2, 3)
    gain = 1.0 + 0.012 * smooth_noise(rng, frames, 1, 0.5 * rate) + 0.006 * smooth_noise(rng, frames, 4, 0.2 * rate)
    return Motion(weights=w, gaze=gaze, head_R=_rotations(head_rv), head_t=head_t,
                  bar_R=_rotations(bar_rv), bar_t=bar_t,
                  caddy_R=_rotations(caddy_rv.reshape(-1, 3)).reshape(frames, 2, 3, 3), caddy_t=caddy_t,
                  gain=gain)
