"""Synthetic face-camera images with painted dots, for training, tests and benchmarks.

The generator draws what a head-mounted camera sees close up: skin with smooth
shading and fine texture, painted markers (black or white ellipses) and the
confusers a face offers — nostrils, eye corners, eyebrows, hair strands, the
edge of the helmet brim and specular highlights.  Markers are rendered by
supersampled coverage, then the whole image is blurred (optics) and noise is
added (sensor), so the true centre of each marker is known exactly.

Coordinates: pixel centres are at integer coordinates (OpenCV's convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class SynthImage:
    """An image and its ground truth.

    Attributes
    ----------
    image : ndarray (H, W) uint8
    centres : ndarray (N, 2) float64
        True centres (x, y) of the markers that count as visible.
    axes : ndarray (N, 2)
        Semi-axes (a >= b) of those markers, pixels.
    hidden : ndarray (M, 2)
        Centres of markers drawn but mostly occluded (neither required nor false).
    brim : ndarray (N,) of bool, optional
        Which of ``centres`` are brim markers (sample-take frames only).
    faint : ndarray (K, 2), optional
        Centres of markers in view whose paint barely changes the image (sample-take
        frames only: black dots on a dense black eyebrow); they are also in ``hidden``.
    names, faint_names : list of str, optional
        Labels of ``centres`` and of ``faint`` (sample-take frames only: ``Brow_L_2``,
        ``Nose_Tip``, ..., the brim's ``Brim_<i>``).
    """

    image: np.ndarray
    centres: np.ndarray
    axes: np.ndarray
    hidden: np.ndarray
    brim: np.ndarray | None = None
    faint: np.ndarray | None = None
    names: list | None = None
    faint_names: list | None = None


def _ellipse_coverage(h, w, cx, cy, a, b, ang, ss=4):
    """Fraction of each pixel inside the ellipse, on the ellipse's bounding box.

    Returns (y0, x0, coverage) with coverage a small float32 array.
    """
    r = int(np.ceil(max(a, b))) + 2
    x0, y0 = int(np.floor(cx)) - r, int(np.floor(cy)) - r
    n = 2 * r + 1
    off = (np.arange(ss) + 0.5) / ss - 0.5
    g = (np.arange(n)[:, None] + off[None, :]).ravel()
    xs = x0 + g - cx
    ys = y0 + g - cy
    c, s = np.cos(ang), np.sin(ang)
    X = xs[None, :] * c + ys[:, None] * s
    Y = -xs[None, :] * s + ys[:, None] * c
    inside = ((X / a) ** 2 + (Y / b) ** 2 <= 1.0).astype(np.float32)
    cov = inside.reshape(n, ss, n, ss).mean(axis=(1, 3))
    return y0, x0, cov


def _paste(dst, y0, x0, cov, value):
    """Blend ``value`` into ``dst`` with weight ``cov`` (clipped to the image)."""
    h, w = dst.shape
    n = cov.shape[0]
    ya, xa = max(0, y0), max(0, x0)
    yb, xb = min(h, y0 + n), min(w, x0 + n)
    if ya >= yb or xa >= xb:
        return
    c = cov[ya - y0:yb - y0, xa - x0:xb - x0]
    reg = dst[ya:yb, xa:xb]
    if np.ndim(value):
        value = value[ya:yb, xa:xb]
    reg *= 1 - c
    reg += c * value


def skin(rng, h, w):
    """Smoothly shaded skin of random tone with fine texture (float32, 0-255)."""
    base = rng.uniform(50, 190)
    small = rng.normal(0, 1, (max(2, h // 64), max(2, w // 64))).astype(np.float32)
    shade = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    img = base * (1 + rng.uniform(0.05, 0.35) * shade)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    gx, gy = rng.uniform(-0.4, 0.4, 2) * base
    img += gx * (xx / w - 0.5) + gy * (yy / h - 0.5)
    tex = cv2.GaussianBlur(rng.normal(0, 1, (h, w)).astype(np.float32), (0, 0), rng.uniform(0.8, 2.0))
    img += tex * rng.uniform(0.5, 4.0) * base / 100
    return np.clip(img, 0, 255).astype(np.float32)


def _confusers(rng, img, white, count):
    """Draw face structures that are not markers."""
    h, w = img.shape
    for _ in range(count):
        kind = rng.choice(["nostril", "corner", "brow", "hair", "brim", "spec", "mole"])
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        if kind == "nostril":
            a, b = rng.uniform(8, 22), rng.uniform(4, 10)
            y0, x0, cov = _ellipse_coverage(h, w, cx, cy, a, b, rng.uniform(0, np.pi), ss=2)
            cov = cv2.GaussianBlur(cov, (0, 0), rng.uniform(1.5, 4))
            _paste(img, y0, x0, cov, img.mean() * rng.uniform(0.1, 0.5))
        elif kind == "corner":
            # A dark wedge: two lines meeting at a point.
            ang = rng.uniform(0, 2 * np.pi)
            spread = rng.uniform(0.2, 0.6)
            L = rng.uniform(15, 50)
            p0 = np.array([cx, cy])
            pts = np.array([p0, p0 + L * np.array([np.cos(ang - spread), np.sin(ang - spread)]),
                            p0 + L * np.array([np.cos(ang + spread), np.sin(ang + spread)])], np.int32)
            m = np.zeros_like(img)
            cv2.fillConvexPoly(m, pts, 1.0, lineType=cv2.LINE_AA)
            m = cv2.GaussianBlur(m, (0, 0), rng.uniform(0.8, 2.0))
            img[:] = img * (1 - m) + m * img.mean() * rng.uniform(0.15, 0.5)
        elif kind in ("brow", "hair"):
            n = rng.integers(15, 60) if kind == "brow" else rng.integers(3, 12)
            ang = rng.uniform(0, np.pi)
            m = np.zeros_like(img)
            for _k in range(n):
                ox, oy = rng.normal(0, 20 if kind == "brow" else 40, 2)
                a2 = ang + rng.normal(0, 0.2)
                L = rng.uniform(6, 20) if kind == "brow" else rng.uniform(30, 120)
                p = np.array([cx + ox, cy + oy])
                q = p + L * np.array([np.cos(a2), np.sin(a2)])
                cv2.line(m, tuple(int(v) for v in p), tuple(int(v) for v in q), 1.0,
                         int(rng.integers(1, 3)), cv2.LINE_AA)
            m = cv2.GaussianBlur(m, (0, 0), 0.7)
            dark = rng.uniform(0.1, 0.5) if not white else rng.uniform(0.1, 0.5)
            img[:] = img * (1 - m) + m * img.mean() * dark
        elif kind == "brim":
            # A straight edge between skin and a dark (or bright) band: the helmet brim.
            ang = rng.uniform(0, np.pi)
            yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
            d = (xx - cx) * np.sin(ang) - (yy - cy) * np.cos(ang)
            wd = rng.uniform(10, 60)
            m = np.clip(0.5 - np.abs(d - wd / 2) + wd / 2, 0, 1) * (np.abs(d) < wd + 2)
            m = cv2.GaussianBlur(m.astype(np.float32), (0, 0), rng.uniform(0.6, 1.5))
            val = rng.uniform(5, 40) if rng.random() < 0.6 else rng.uniform(200, 255)
            img[:] = img * (1 - m) + m * val
        elif kind == "spec":
            sig = rng.uniform(2, 6)
            y0, x0 = int(cy) - 20, int(cx) - 20
            g = np.zeros((41, 41), np.float32)
            g[20, 20] = 1
            g = cv2.GaussianBlur(g, (0, 0), sig)
            g /= g.max()
            _paste(img, y0, x0, g * rng.uniform(0.3, 0.9), 255.0)
        else:  # mole / pore: tiny soft dark spot, below marker size
            y0, x0, cov = _ellipse_coverage(h, w, cx, cy, 1.0, 0.8, 0.0)
            cov = cv2.GaussianBlur(cov, (0, 0), 1.2)
            _paste(img, y0, x0, cov, img.mean() * 0.5)


def render(rng, h=360, w=480, markers=40, white=False, radius=(2.0, 7.0), aspect=(0.55, 1.0),
           blur=(0.5, 1.4), noise=(0.5, 5.0), confusers=8, occluders=True, min_spacing=None) -> SynthImage:
    """Render one image with random markers and confusers.

    Parameters
    ----------
    rng : numpy.random.Generator
    h, w : int
        Image size.
    markers : int
        Markers to try to place (fewer if spacing forbids).
    white : bool
        White markers instead of black.
    radius, aspect, blur, noise : (low, high)
        Ranges of the semi-major axis (px), minor/major ratio, optical blur sigma
        (px) and noise sigma (grey levels).
    confusers : int
        Face structures to draw.
    occluders : bool
        Let some brim edges cross markers (partial occlusion).
    """
    img = skin(rng, h, w)
    _confusers(rng, img, white, confusers)
    centres, axes = [], []
    spacing = min_spacing or 2.5 * radius[1] + 4
    tries = 0
    while len(centres) < markers and tries < markers * 20:
        tries += 1
        a = rng.uniform(*radius)
        b = a * rng.uniform(*aspect)
        cx, cy = rng.uniform(a + 3, w - a - 4), rng.uniform(a + 3, h - a - 4)
        if centres and np.min(np.hypot(*(np.array(centres) - (cx, cy)).T)) < spacing:
            continue
        y0, x0, cov = _ellipse_coverage(h, w, cx, cy, a, b, rng.uniform(0, np.pi))
        sk = img[int(cy), int(cx)]
        if white:
            val = min(255.0, sk + rng.uniform(40, 150))
        else:
            val = sk * rng.uniform(0.05, 0.55)
        if abs(val - sk) < 20:
            continue
        _paste(img, y0, x0, cov, val)
        centres.append((cx, cy))
        axes.append((a, b))
    centres = np.array(centres, float).reshape(-1, 2)
    axes = np.array(axes, float).reshape(-1, 2)
    hidden = np.zeros((0, 2))
    if occluders and len(centres) and rng.random() < 0.5:
        # A dark band (the brim) across the image: markers it touches are partly or
        # wholly hidden, so they are neither required nor counted as false.
        ang = rng.uniform(0, np.pi)
        px, py = rng.uniform(0, w), rng.uniform(0, h)
        wd = rng.uniform(20, 80)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        d = (xx - px) * np.sin(ang) - (yy - py) * np.cos(ang)
        m = np.clip(np.minimum(0.5 + d, 0.5 + wd - d), 0, 1).astype(np.float32)
        m = cv2.GaussianBlur(m, (0, 0), 0.8)
        img[:] = img * (1 - m) + m * rng.uniform(5, 40)
        dc = (centres[:, 0] - px) * np.sin(ang) - (centres[:, 1] - py) * np.cos(ang)
        touched = (dc > -axes[:, 0] - 1.5) & (dc < wd + axes[:, 0] + 1.5)
        hidden = centres[touched]
        centres, axes = centres[~touched], axes[~touched]
    return SynthImage(_optics(rng, img, blur, noise), centres, axes, hidden)


def _optics(rng, img, blur, noise):
    """The camera: optical blur and sensor noise (sigmas drawn from the ``(low, high)`` ranges), as uint8."""
    img = cv2.GaussianBlur(img, (0, 0), rng.uniform(*blur))
    sig = rng.uniform(*noise)
    img = img + rng.normal(0, 1, img.shape).astype(np.float32) * sig
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _clipped(img, y0, x0, n):
    """The ``n`` x ``n`` block of ``img`` from ``(y0, x0)``, zero where it lies outside the image."""
    out = np.zeros((n, n), img.dtype)
    h, w = img.shape
    ya, xa, yb, xb = max(0, y0), max(0, x0), min(h, y0 + n), min(w, x0 + n)
    if ya < yb and xa < xb:
        out[ya - y0:yb - y0, xa - x0:xb - x0] = img[ya:yb, xa:xb]
    return out


def _paint(rng, white, under):
    """Grey level of a dot painted on skin of grey level ``under``."""
    return min(255.0, under + rng.uniform(40, 150)) if white else under * rng.uniform(0.05, 0.55)


#: Kinds of face structure :func:`render_grazing` puts thin dots beside.
GRAZING_KINDS = ("silhouette", "nostril", "mouth")


def _silhouette(rng, img, shade, beyond, xx, yy, p, dots):
    """The face's outline near one side of the image: shading towards it, the dark beyond (in place).

    Returns the thin dots' places ``(cx, cy, room, angle)`` 1-6 px inside it, tangent to it.
    """
    h, w = img.shape
    side = int(rng.integers(4))  # left, right, top, bottom
    n0 = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]][side], float)
    inset, slide = rng.uniform(0.1, 0.3), rng.uniform(-0.35, 0.35)
    p = np.array([w / 2, h / 2]) + np.abs(n0[::-1]) * slide * (w, h) + n0 * (0.5 - inset) * (w, h)
    t0 = rng.uniform(-0.5, 0.5)
    n = np.array([np.cos(t0) * n0[0] - np.sin(t0) * n0[1], np.sin(t0) * n0[0] + np.cos(t0) * n0[1]])
    R = rng.uniform(200, 1500)
    c = p - R * n
    depth = R - np.hypot(xx - c[0], yy - c[1])  # inside the face > 0
    fall, rim = rng.uniform(3, 15), rng.uniform(0.2, 0.45)
    shade *= np.where(depth > 0, rim + (1 - rim) * np.sqrt(np.clip(depth / fall, 0, 1)), 1)
    beyond[:] = np.maximum(beyond, np.clip(0.5 - depth, 0, 1))
    placed = []
    for _ in range(dots):
        t = rng.uniform(-0.6, 0.6) * min(h, w) / R
        d = rng.uniform(1.0, 6.0)
        u = np.array([np.cos(t) * n[0] - np.sin(t) * n[1], np.sin(t) * n[0] + np.cos(t) * n[1]])
        q = c + (R - d) * u
        placed.append((q[0], q[1], d, np.arctan2(u[1], u[0]) + np.pi / 2))
    return placed


def _nostril(rng, img, shade, beyond, xx, yy, p, dots):
    """A soft dark ellipse at ``p`` (in place); returns the thin dots' places 1-4 px outside its rim."""
    h, w = img.shape
    a, b, ang = rng.uniform(8, 20), rng.uniform(4, 9), rng.uniform(0, np.pi)
    y0, x0, cov = _ellipse_coverage(h, w, p[0], p[1], a, b, ang, ss=2)
    cov = cv2.GaussianBlur(cov, (0, 0), rng.uniform(1.0, 3.0))
    _paste(img, y0, x0, cov, img[int(p[1]), int(p[0])] * rng.uniform(0.1, 0.4))
    placed = []
    for _ in range(dots):
        t = rng.uniform(0, 2 * np.pi)
        e = np.array([a * np.cos(t), b * np.sin(t)])
        rim = p + [e[0] * np.cos(ang) - e[1] * np.sin(ang), e[0] * np.sin(ang) + e[1] * np.cos(ang)]
        out = (rim - p) / np.linalg.norm(rim - p)
        d = rng.uniform(1.0, 4.0)
        q = rim + d * out
        placed.append((q[0], q[1], d, np.arctan2(out[1], out[0]) + np.pi / 2))
    return placed


def _mouth(rng, img, shade, beyond, xx, yy, p, dots):
    """A dark band with a bright band (the teeth) along one side, through ``p`` (in place).

    Returns the thin dots' places on the dark band, 1-4 px from the bright one.
    """
    ang = rng.uniform(0, np.pi)
    n = np.array([-np.sin(ang), np.cos(ang)])
    s = (xx - p[0]) * n[0] + (yy - p[1]) * n[1]
    along = (xx - p[0]) * np.cos(ang) + (yy - p[1]) * np.sin(ang)
    half = rng.uniform(40, 120)
    dark_w, teeth_w = rng.uniform(6, 20), rng.uniform(4, 12)
    inside = np.clip(half + 0.5 - np.abs(along), 0, 1)
    dark = np.clip(np.minimum(s + 0.5, dark_w + 0.5 - s), 0, 1) * inside
    teeth = np.clip(np.minimum(0.5 - s, teeth_w + 0.5 + s), 0, 1) * inside
    img[:] = img * (1 - dark * rng.uniform(0.55, 0.85))
    img[:] = img * (1 - teeth) + teeth * rng.uniform(150, 245)
    placed = []
    for _ in range(dots):
        d = rng.uniform(1.0, 4.0)
        q = p + rng.uniform(-0.9, 0.9) * half * np.array([np.cos(ang), np.sin(ang)]) + d * n
        placed.append((q[0], q[1], d, ang))
    return placed


_GRAZING_PLACES = {"silhouette": _silhouette, "nostril": _nostril, "mouth": _mouth}


def render_grazing(rng, h=360, w=480, white=False, structures=3, dots=5, markers=10, minor=(0.4, 1.4),
                   major=(2.5, 6.0), blur=(0.5, 1.2), noise=(0.5, 4.0), confusers=4) -> SynthImage:
    """Render thin dots seen at grazing angles beside the dark structures of a face.

    The views the classifier finds hardest on the sample takes: dots whose surface faces the
    camera at 70-85 degrees, so that they are ellipses of minor semi-axis 0.4-1.4 px, drawn
    tangent to (``structures`` of, cycling through :data:`GRAZING_KINDS`)

    - ``silhouette``: the face's outline, the skin shaded darker towards it (Lambertian
      fall-off over 3-15 px) against the dark beyond it; dots 1-6 px inside it (cheek,
      temple and jaw dots near the outline, chin dots seen edge-on);
    - ``nostril``: a soft dark ellipse; dots 1-4 px outside its rim (nostril dots);
    - ``mouth``: the dark band of the open mouth or of the jaw's shadow beside a bright band
      (the teeth); dots on the dark band 1-4 px from the bright one (lower-lip dots with the
      jaw open).

    Each structure carries ``dots`` such dots; ``markers`` ordinary dots (semi-axes 1.8-7 px)
    and ``confusers`` confusers keep the rest of the face in the picture. Painted dots are
    shaded with the skin under them (shading multiplies the albedo of paint and skin alike).

    Returns
    -------
    SynthImage
        ``centres`` and ``axes`` of the dots required; a thin dot reaching past the structure's edge
        or past an outline drawn later, or whose paint the shade leaves under 10 grey levels of
        contrast, is in ``hidden`` (neither required nor false).
    """
    img = skin(rng, h, w)
    _confusers(rng, img, white, confusers)
    shade = np.ones((h, w), np.float32)
    beyond = np.zeros((h, w), np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    placed = []  # (cx, cy, room: px to the structure's edge, angle of the major axis)
    for k in range(structures):
        kind = GRAZING_KINDS[k % len(GRAZING_KINDS)]
        p = rng.uniform((w * 0.15, h * 0.15), (w * 0.85, h * 0.85))
        for _ in range(10):  # a nostril or a mouth inside the face
            if beyond[int(p[1]), int(p[0])] == 0:
                break
            p = rng.uniform((w * 0.15, h * 0.15), (w * 0.85, h * 0.85))
        placed += _GRAZING_PLACES[kind](rng, img, shade, beyond, xx, yy, p, dots)
    centres, axes, hidden, taken = [], [], [], []  # taken: (x, y, semi-major) of every dot drawn

    def free(cx, cy, a, gap):
        return all(np.hypot(cx - x, cy - y) >= a + r + gap for x, y, r in taken)

    for cx, cy, room, ang in placed:
        a, b = rng.uniform(*major), rng.uniform(*minor)
        if not (a + 3 < cx < w - a - 4 and a + 3 < cy < h - a - 4) or not free(cx, cy, a, 3):
            continue
        under = float(img[int(round(cy)), int(round(cx))])
        val = _paint(rng, white, under)
        y0, x0, cov = _ellipse_coverage(h, w, cx, cy, a, b, ang)
        _paste(img, y0, x0, cov, val)
        taken.append((cx, cy, a))
        cut = _clipped(beyond, y0, x0, cov.shape[0])
        # A dot reaching past an outline, or whose paint the shade leaves under 10 grey levels, is not required.
        if b < room and not (cut * cov).any() \
                and abs(val - under) * shade[int(round(cy)), int(round(cx))] >= 10:
            centres.append((cx, cy))
            axes.append((a, b))
        else:
            hidden.append((cx, cy))
    for _ in range(markers):  # ordinary dots, away from the thin ones and the outline
        a = rng.uniform(1.8, 7.0)
        b = a * rng.uniform(0.55, 1.0)
        cx, cy = rng.uniform(a + 3, w - a - 4), rng.uniform(a + 3, h - a - 4)
        if shade[int(cy), int(cx)] < 1 or beyond[int(cy), int(cx)] > 0 or not free(cx, cy, a, 8):
            continue
        under = float(img[int(cy), int(cx)])
        val = _paint(rng, white, under)
        if abs(val - under) < 20:
            continue
        y0, x0, cov = _ellipse_coverage(h, w, cx, cy, a, b, rng.uniform(0, np.pi))
        _paste(img, y0, x0, cov, val)
        taken.append((cx, cy, a))
        centres.append((cx, cy))
        axes.append((a, b))
    img *= shade
    img[:] = img * (1 - beyond) + beyond * rng.uniform(8, 40)
    return SynthImage(_optics(rng, img, blur, noise), np.array(centres, float).reshape(-1, 2),
                      np.array(axes, float).reshape(-1, 2), np.array(hidden, float).reshape(-1, 2))


def disc_image(rng, size=41, radius=4.0, blur=1.0, amplitude=100.0, background=60.0, sigma=1.0,
               centre=None, dark=False):
    """An isolated blurred disc with Gaussian noise (float32, not quantised), and its centre.

    Signal-to-noise is ``amplitude / sigma``.
    """
    if centre is None:
        centre = (size // 2 + rng.uniform(-0.5, 0.5), size // 2 + rng.uniform(-0.5, 0.5))
    cx, cy = centre
    # 32x32 samples per pixel: coarser sampling shifts the rendered centre by ~0.005 px.
    y0, x0, cov = _ellipse_coverage(size, size, cx, cy, radius, radius, 0.0, ss=32)
    img = np.zeros((size, size), np.float32)
    _paste(img, y0, x0, cov, 1.0)
    img = cv2.GaussianBlur(img, (0, 0), blur) if blur > 0 else img
    s = -1.0 if dark else 1.0
    img = background + s * amplitude * img + rng.normal(0, sigma, img.shape).astype(np.float32)
    return img, np.array(centre)


def sample_frames(white: bool = False, seed: int = 0, frames: int = 2, step: int = 40, markers: int = 100,
                  noise: float | None = None, blur: float | None = None, cameras=(0, 1, 2, 3),
                  jaw_open: int = 0, take_frames: int | None = None, perspective_dots: bool = True) -> list[SynthImage]:
    """Frames of a ``carapost sample`` take (all its cameras), rendered in memory, with their truth.

    The same renderer as ``carapost sample`` (:mod:`carapost.sample`): a face with
    painted dots, brows, eyes, lips, hair and the brim with its printed dots, under
    the helmet's lights.  ``centres`` are the centres of the visible markers' images (face and brim);
    markers drawn but partly covered are ``hidden`` (neither required nor false), and
    so are the ``faint`` ones: in view, but their paint barely changes the image
    (:data:`FAINT`; black dots painted on a dense black eyebrow look like the brow).

    Parameters
    ----------
    white : bool
        White markers (on a dark brim) instead of black.
    seed : int
        The take's seed (the same as ``carapost sample --seed``).
    frames, step : int
        Frames ``0, step, 2 step, ...`` of the take, ``frames`` of them.
    markers : int
        Painted face markers.
    noise, blur : float, optional
        Sensor noise (grey levels) and optical blur (px); the sample's defaults if omitted.
    cameras : sequence of int
        Which of the four cameras.
    jaw_open : int
        Instead of ``frames`` and ``step``: this many frames of a ``take_frames``-frame take (120 by
        default) where the jaw is open widest (its lower-lip and chin dots seen at grazing angles in the
        jaw's shadow, beside the teeth), each a frame apart from the next.
    take_frames : int, optional
        The length of the take the frames belong to (by default just long enough to hold them).  The
        take's motion is drawn over its whole length, so frame 0 of a 300-frame ``carapost sample`` take
        is rendered as it is only with ``take_frames=300``.
    perspective_dots : bool
        Dots drawn under perspective, as by ``carapost sample``: ``centres`` are their images' centres, a few
        hundredths of a pixel off their centres' projections (False: ``--linear-dots``, centred on them).
    """
    # Imported here: the renderer is a consumer of the core, not a part of it.
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras

    kw = {k: float(v) for k, v in (("noise", noise), ("blur", blur)) if v is not None}
    if jaw_open:
        length = int(take_frames or 120)
    else:
        length = max(1, (frames - 1) * step + 1, int(take_frames or 0))
    sc = build_scene(markers=markers, frames=length, seed=seed, white=white, perspective_dots=perspective_dots, **kw)
    labels = np.array(list(sc.markers.labels) + [f"Brim_{i}" for i in range(sc.n_brim)])
    out = []
    if jaw_open:
        from carapost.sample.face import EXPRESSIONS

        jaw = sc.motion.weights[:, EXPRESSIONS.index("jaw_open")]
        widest = int(np.argmax(jaw))
        which = [min(max(widest + k - jaw_open // 2, 0), length - 1) for k in range(int(jaw_open))]
    else:
        which = range(0, frames * step, step)
    for f in which:
        g = frame_geometry(sc, f)
        cams = true_cameras(sc, f)
        for c in cameras:
            img, tr = render_view(sc, g, cams[c], c, f, leds=leds_of(cams))
            # The same view without paint (same noise stream): what each dot changes.
            bare, _ = render_view(sc, g, cams[c], c, f, leds=leds_of(cams), markers=False)
            # A detector's target is the centre of each dot's image (a few hundredths of a pixel off the
            # projection of its centre; the brim's solves take that offset off).
            at = tr.centre
            brim = np.zeros(len(at), bool)
            brim[len(at) - sc.n_brim:] = True
            vis = np.flatnonzero(tr.visible)
            paint = paint_contrast(img, bare, at[vis], tr.axes[vis], white)
            # Thin dots (edge-on) are left required: blur spreads their paint, so their mean change is low.
            faint = (paint < FAINT * np.median(paint)) & (tr.axes[vis, 1] >= 1.5) if len(vis) else np.zeros(0, bool)
            keep = vis[~faint]
            hidden = np.concatenate([at[tr.drawn & ~tr.visible], at[vis[faint]]])
            s = SynthImage(img, at[keep], tr.axes[keep], hidden, brim[keep], at[vis[faint]],
                           labels[keep].tolist(), labels[vis[faint]].tolist())
            out.append(s)
    return out


#: A dot in view is "faint" (not required, not false) when its paint changes the grey level inside it by
#: less than this fraction of the view's median: black paint on a dense black eyebrow changes it by
#: 0-25 grey levels where every other black dot of the sample takes changes it by 48-150 (median 105).
#: Only dots of minor semi-axis >= 1.5 px can be faint.
FAINT = 0.25


def paint_contrast(image: np.ndarray, bare: np.ndarray, uv: np.ndarray, axes: np.ndarray, white: bool) -> np.ndarray:
    """Mean change of the grey level the paint makes inside each dot (positive towards the paint's colour).

    Parameters
    ----------
    image, bare : ndarray (H, W)
        The view with and without the painted dots (same noise).
    uv : ndarray (N, 2)
        Dot centres (x, y).
    axes : ndarray (N, 2)
        Semi-axes (major, minor), px: the mean is over the disc of 0.6 x the minor semi-axis
        (at least 1 px), which lies inside the dot whatever its orientation.
    white : bool
        White paint (brighter) or black (darker).
    """
    diff = (image.astype(np.float32) - bare.astype(np.float32)) * (1.0 if white else -1.0)
    h, w = diff.shape
    out = np.zeros(len(uv))
    for k, ((x, y), (_a, b)) in enumerate(zip(np.asarray(uv, float), np.asarray(axes, float))):
        r = max(1.0, 0.6 * b)
        x0, x1 = max(0, int(np.floor(x - r))), min(w, int(np.ceil(x + r)) + 1)
        y0, y1 = max(0, int(np.floor(y - r))), min(h, int(np.ceil(y + r)) + 1)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        m = np.hypot(xx - x, yy - y) <= r
        out[k] = diff[y0:y1, x0:x1][m].mean() if m.any() else 0.0
    return out


def match_truth(points: np.ndarray, truth: SynthImage, tol: float = 1.5, hidden_px: float = 6.0):
    """Score detected centres against one image's truth.

    A point within ``tol`` px of a visible marker's centre is a hit (one per marker,
    nearest first); a point within ``hidden_px`` of a hidden marker is neither hit
    nor false; any other point is false.

    Returns
    -------
    hit : ndarray of bool (len(truth.centres),)
        Which markers were found.
    false : int
        False detections.
    errors : ndarray (hits, 2)
        Detected minus true centre of each hit.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, float).reshape(-1, 2)
    hit = np.zeros(len(truth.centres), bool)
    if len(pts) == 0 or len(truth.centres) == 0:
        return hit, len(pts), np.zeros((0, 2))
    d, j = cKDTree(truth.centres).query(pts)
    hidden = cKDTree(truth.hidden) if len(truth.hidden) else None
    errs, false = [], 0
    for k in np.argsort(d, kind="stable"):
        if d[k] <= tol and not hit[j[k]]:
            hit[j[k]] = True
            errs.append(pts[k] - truth.centres[j[k]])
        elif hidden is None or hidden.query(pts[k])[0] >= hidden_px:
            false += 1
    return hit, false, np.array(errs, float).reshape(-1, 2)
