"""Albedo (reflectance) textures of the face, the eyelids, the mouth and the brim, in one atlas.

The cameras are monochrome, so albedo is one grey value in 0..1.  The face
carries what confuses a marker detector on a real face: eyebrow hairs, the
hairline, nostrils, lashes, lips, teeth and a dark mouth, moles, and skin
texture at several scales.  The painted markers are *not* in the texture: they
are drawn per frame with exact area coverage (:mod:`.coverage`).

The atlas is sampled in texel coordinates (texel ``(i, j)`` centred at
``(x=j, y=i)``, OpenCV's convention); :class:`Atlas` maps each surface's
parameters to them.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .face import (EYE_HALF, EYE_U, EYE_V, EYELID_A, EYELID_T_MM, FACE_U, FACE_V, MOUTH_HALF, MOUTH_V,
                   eye_margins, hairline)
from .rig import BRIM_SIZE

__all__ = ["TEX_PER_MM", "Atlas", "make_atlas", "SKIN", "SCLERA"]

TEX_PER_MM = 4.0
SKIN = 0.54
SCLERA = 0.74
_M = 2          # margin (texels) around each region, so bilinear lookups stay inside it

# Region origins (texel x, y) and sizes.
_FACE_W = int(round((FACE_U[1] - FACE_U[0]) * TEX_PER_MM)) + 2 * _M + 1
_FACE_H = int(round((FACE_V[1] - FACE_V[0]) * TEX_PER_MM)) + 2 * _M + 1
_LID_W = int(round(2 * EYELID_A * EYE_HALF * TEX_PER_MM)) + 2 * _M + 1
_LID_H = int(round(EYELID_T_MM * TEX_PER_MM)) + 2 * _M + 1
_BAND_ROWS = 64           # the lip band, s = -1..1, is stretched over this many texel rows
_BAND_W = int(round(2 * MOUTH_HALF * TEX_PER_MM)) + 2 * _M + 1
_BAND_H = _BAND_ROWS + 2 * _M + 1
_BRIM_W = int(round(BRIM_SIZE[0] * TEX_PER_MM)) + 2 * _M + 1
_BRIM_H = int(round(BRIM_SIZE[1] * TEX_PER_MM)) + 2 * _M + 1

_ORIGIN = {
    "face": (0, 0),
    "lid_L": (0, _FACE_H),
    "lid_R": (_LID_W, _FACE_H),
    "band": (2 * _LID_W, _FACE_H),
    "brim": (0, _FACE_H + max(_LID_H, _BAND_H)),
    "bg": (0, _FACE_H + max(_LID_H, _BAND_H) + _BRIM_H),
}
_ATLAS_W = max(_FACE_W, _BRIM_W, 2 * _LID_W + _BAND_W)
_ATLAS_H = _ORIGIN["bg"][1] + 8


@dataclass
class Atlas:
    """The albedo atlas and the mappings from surface parameters to texels.

    Attributes
    ----------
    image : ndarray, shape (H, W), float32
        Albedo, 0..1.
    """

    image: np.ndarray

    @staticmethod
    def face(u, v):
        """Texel coordinates of skin parameters ``(u, v)``."""
        x0, y0 = _ORIGIN["face"]
        return (x0 + _M + (np.asarray(u) - FACE_U[0]) * TEX_PER_MM,
                y0 + _M + (np.asarray(v) - FACE_V[0]) * TEX_PER_MM)

    @staticmethod
    def lid(side: int, a, t):
        """Texel coordinates of eyelid parameters ``(a, t)`` (side +1 left, -1 right)."""
        x0, y0 = _ORIGIN["lid_L" if side > 0 else "lid_R"]
        return (x0 + _M + (np.asarray(a) + EYELID_A) * EYE_HALF * TEX_PER_MM,
                y0 + _M + np.asarray(t) * EYELID_T_MM * TEX_PER_MM)

    @staticmethod
    def band(u, v):
        """Texel coordinates of the lip band at skin parameters ``(u, v)``."""
        x0, y0 = _ORIGIN["band"]
        s = np.asarray(v) - MOUTH_V
        return (x0 + _M + (np.asarray(u) + MOUTH_HALF) * TEX_PER_MM,
                y0 + _M + (s + 1.0) * 0.5 * _BAND_ROWS)

    @staticmethod
    def brim(x, y):
        """Texel coordinates of brim-plate point ``(x, y)`` (brim mm)."""
        x0, y0 = _ORIGIN["brim"]
        return (x0 + _M + (np.asarray(x) + BRIM_SIZE[0] / 2) * TEX_PER_MM,
                y0 + _M + (np.asarray(y) + BRIM_SIZE[1] / 2) * TEX_PER_MM)

    @staticmethod
    def background():
        """Texel coordinates of the background colour."""
        x0, y0 = _ORIGIN["bg"]
        return (x0 + 4.0, y0 + 4.0)


def _field(rng, shape, sigma_texels) -> np.ndarray:
    """Smooth random field with unit standard deviation."""
    n = rng.standard_normal(shape).astype(np.float32)
    if sigma_texels > 0.3:
        n = cv2.GaussianBlur(n, (0, 0), sigma_texels, borderType=cv2.BORDER_REFLECT)
    s = float(n.std())
    return n / s if s > 0 else n


def _grid(region: str, w: int, h: int):
    """Parameter grids of a region's texels (inverse of the Atlas mappings)."""
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    return jj - _M, ii - _M


def _strokes_fast(layer: np.ndarray, p0, p1, darkness, thickness: int = 1) -> None:
    """Anti-aliased lines (hairs) added into a darkness layer (texel coordinates).

    Hairs are drawn in a few darkness groups, each clipped to its level, so
    crossing hairs do not add up to more than the darkest of them by much.
    """
    levels = np.linspace(0.3, 1.0, 6)
    d = np.asarray(darkness)
    for lo, hi in zip(levels[:-1], levels[1:]):
        sel = (d >= lo) & (d < hi + 1e-9)
        if not np.any(sel):
            continue
        tmp = np.zeros_like(layer)
        for (x0, y0), (x1, y1) in zip(np.asarray(p0)[sel], np.asarray(p1)[sel]):
            cv2.line(tmp, (int(round(x0 * 16)), int(round(y0 * 16))), (int(round(x1 * 16)), int(round(y1 * 16))),
                     1.0, thickness, cv2.LINE_AA, 4)
        layer += 0.5 * (lo + hi) * np.minimum(tmp, 1.0)


def _face_texture(rng: np.random.Generator, avoid: np.ndarray) -> np.ndarray:
    tp = TEX_PER_MM
    jj, ii = _grid("face", _FACE_W, _FACE_H)
    u = FACE_U[0] + jj / tp
    v = FACE_V[0] + ii / tp
    shape = u.shape
    alb = np.full(shape, SKIN, np.float32)
    # Skin: blotches, finer mottling, pores.
    alb += 0.035 * _field(rng, shape, 6.0 * tp)
    alb += 0.018 * _field(rng, shape, 1.2 * tp)
    alb += 0.016 * _field(rng, shape, 0.3 * tp)
    dark = np.zeros(shape, np.float32)    # multiplicative darkening (hair, lashes, ...), 0..1

    def tex(uu, vv):
        return (np.asarray(uu) - FACE_U[0]) * tp, (np.asarray(vv) - FACE_V[0]) * tp

    # Hair: dark above the hairline, with strands, and single hairs hanging below it.
    hl = hairline(u)
    edge = np.clip((hl - v) / 2.5 + 0.5, 0.0, 1.0)
    dark = np.maximum(dark, 0.86 * edge.astype(np.float32))
    n = 2500
    hu = rng.uniform(FACE_U[0], FACE_U[1], n)
    hv = hairline(hu) + rng.uniform(-25.0, 4.0, n)
    ang = np.radians(90.0 + rng.normal(0.0, 25.0, n) + 0.4 * hu)
    ln = rng.uniform(3.0, 9.0, n)
    p0 = np.column_stack(tex(hu, hv))
    p1 = np.column_stack(tex(hu + ln * np.cos(ang) * 0.5, hv + ln * np.sin(ang)))
    _strokes_fast(dark, p0, p1, rng.uniform(0.5, 0.95, n))
    # Eyebrows: arcs of hairs, dense in the middle, pointing up at the inner end
    # and sideways further out.
    for side in (1.0, -1.0):
        n = 700
        x = rng.beta(1.6, 1.4, n)                         # 0 inner end .. 1 outer end
        bu = side * (11.0 + 37.0 * x)
        centre = -44.5 - 6.0 * np.sin(np.pi * np.clip(x * 1.15, 0, 1)) + 2.0 * x
        thick = 7.0 - 4.0 * x
        bv = centre + rng.normal(0.0, 0.28, n) * thick
        ang = np.radians(np.where(x < 0.25, -75.0 + 200.0 * x, -25.0 + 45.0 * x) + rng.normal(0, 12, n))
        ln = rng.uniform(2.5, 5.0, n)
        p0 = np.column_stack(tex(bu, bv))
        p1 = np.column_stack(tex(bu + side * ln * np.cos(ang), bv + ln * np.sin(ang)))
        _strokes_fast(dark, p0, p1, rng.uniform(0.45, 0.9, n))
    # Eyes: sclera in the opening (the iris is drawn per frame, it moves), a
    # pinkish caruncle at the inner corner, the lower lash line, a darker socket.
    for side in (1.0, -1.0):
        up, lo, _ = eye_margins(u, int(side))
        x = (u - side * EYE_U) / EYE_HALF
        inside = (np.abs(x) < 1.0) & (v > up - 0.3) & (v < lo + 0.3)
        scl = SCLERA - 0.12 * np.abs(x) ** 3
        alb = np.where(inside, scl, alb)
        car = np.exp(-0.5 * ((x * side + 0.93) / 0.06) ** 2) * inside     # x * side = -1 at the inner corner
        alb = alb * (1 - car) + 0.42 * car
        socket = np.exp(-0.5 * ((u - side * EYE_U) / 14.0) ** 2 - 0.5 * ((v - EYE_V) / 9.0) ** 2)
        alb *= (1.0 - 0.1 * socket).astype(np.float32)
        lash = np.exp(-0.5 * ((v - lo - 0.35) / 0.3) ** 2) * (np.abs(x) < 1.0) * (1.0 - 0.6 * np.abs(x))
        dark = np.maximum(dark, (0.6 * lash).astype(np.float32))
        n = 60
        lu = side * EYE_U + rng.uniform(-0.9, 0.9, n) * EYE_HALF
        lv = eye_margins(lu, int(side))[1] + 0.4
        p0 = np.column_stack(tex(lu, lv))
        p1 = np.column_stack(tex(lu + side * rng.uniform(0.2, 0.8, n), lv + rng.uniform(0.8, 1.8, n)))
        _strokes_fast(dark, p0, p1, rng.uniform(0.4, 0.7, n))
    # Nostrils: dark ovals under the nose tip (seen from the lower cameras).
    for side in (1.0, -1.0):
        c, s = np.cos(np.radians(side * 28.0)), np.sin(np.radians(side * 28.0))
        du, dv = u - side * 6.8, v - 5.0
        q = ((c * du + s * dv) / 3.1) ** 2 + ((-s * du + c * dv) / 1.9) ** 2
        dark = np.maximum(dark, (0.93 * np.clip(1.6 - q, 0.0, 1.0) ** 1.5).astype(np.float32))
    # Lips: darker vermilion, cupid's bow on top.
    au = np.abs(u)
    w = np.clip(1.0 - (au / (MOUTH_HALF + 1.0)) ** 2, 0.0, None)
    top = MOUTH_V - 6.8 * w ** 0.6 + 1.2 * np.exp(-0.5 * (u / 2.0) ** 2) - 1.0 * np.exp(-0.5 * ((au - 5.0) / 3.0) ** 2)
    bot = MOUTH_V + 6.5 * w ** 0.7
    lip = np.clip((v - top) / 0.6 + 0.5, 0, 1) * np.clip((bot - v) / 0.8 + 0.5, 0, 1) * (w > 0)
    alb = alb * (1.0 - lip) + (0.43 + 0.02 * _field(rng, shape, 0.8 * tp)) * lip
    # Moles and freckles: small dark spots, a few of them dot-like (detector confusers),
    # kept away from the painted markers so they do not bias the markers' centres.
    k = 0
    tries = 0
    while k < 9 and tries < 500:
        tries += 1
        mu, mv = rng.uniform(-60, 60), rng.uniform(-75, 85)
        if avoid.size and np.min(np.hypot(avoid[:, 0] - mu, avoid[:, 1] - mv)) < 5.0:
            continue
        if (mu / 62.0) ** 2 + ((mv - 5.0) / 85.0) ** 2 > 1.0 or mv < hairline(mu) + 3:
            continue
        r = rng.uniform(0.35, 1.1)
        d2 = (u - mu) ** 2 + (v - mv) ** 2
        dark = np.maximum(dark, (rng.uniform(0.25, 0.6) * np.clip((r - np.sqrt(d2)) / 0.3 + 0.5, 0, 1))
                          .astype(np.float32))
        k += 1
    out = alb * (1.0 - np.clip(dark, 0.0, 0.92))
    # Towards the rim of the skin sheet (temples, jaw line, under the chin) the
    # head turns away into shadow and hair: fade, so the sheet has no hard edge.
    rho = np.sqrt((u / 75.0) ** 2 + ((v + 3.0) / 103.0) ** 2)
    t = np.clip((rho - 0.84) / 0.16, 0.0, 1.0)
    out *= 1.0 - 0.8 * t * t * (3 - 2 * t)
    return out.astype(np.float32)


def _lid_texture(rng: np.random.Generator) -> np.ndarray:
    jj, ii = _grid("lid", _LID_W, _LID_H)
    t = ii / (EYELID_T_MM * TEX_PER_MM)
    alb = np.full(jj.shape, SKIN * 0.94, np.float32)
    alb += 0.02 * _field(rng, jj.shape, 1.0 * TEX_PER_MM) + 0.012 * _field(rng, jj.shape, 0.3 * TEX_PER_MM)
    alb *= (1.0 - 0.15 * np.exp(-0.5 * (t / 0.08) ** 2)).astype(np.float32)            # the crease
    lash = np.clip((t - 0.9) / 0.05, 0.0, 1.0)                                            # lash line
    alb = alb * (1 - 0.82 * lash)
    return alb.astype(np.float32)


def _band_texture(rng: np.random.Generator) -> np.ndarray:
    jj, ii = _grid("band", _BAND_W, _BAND_H)
    u = -MOUTH_HALF + jj / TEX_PER_MM
    s = ii / (0.5 * _BAND_ROWS) - 1.0
    # From the upper lip inwards: inner lip, upper teeth, the dark mouth, lower
    # teeth, inner lower lip.  The band stretches as the jaw opens, so the
    # teeth are kept narrow in s (a few mm tall in a wide-open mouth).
    alb = np.full(jj.shape, 0.05, np.float32)
    seam = 1.0 - 0.3 * np.exp(-0.5 * ((np.mod(u + 4.5, 9.0) - 4.5) / 0.4) ** 2)
    alb = np.where(np.abs(s) > 0.72, 0.34, alb)
    alb = np.where((s > -0.72) & (s < -0.5), 0.62 * seam, alb)
    alb = np.where((s > 0.52) & (s < 0.72), 0.55 * seam, alb)
    # Towards the corners the mouth is in shadow.
    alb *= (1.0 - 0.8 * np.clip((np.abs(u) - 16.0) / 9.0, 0.0, 1.0)).astype(np.float32)
    alb += 0.01 * _field(rng, jj.shape, 1.0)
    return cv2.GaussianBlur(alb.astype(np.float32), (0, 0), 0.8)


def _brim_texture(rng: np.random.Generator, white_markers: bool) -> np.ndarray:
    jj, ii = _grid("brim", _BRIM_W, _BRIM_H)
    x = -BRIM_SIZE[0] / 2 + jj / TEX_PER_MM
    y = -BRIM_SIZE[1] / 2 + ii / TEX_PER_MM
    base = 0.07 if white_markers else 0.62
    alb = np.full(jj.shape, base, np.float32) + 0.01 * _field(rng, jj.shape, 2.0)
    border = np.minimum(BRIM_SIZE[0] / 2 - np.abs(x), BRIM_SIZE[1] / 2 - np.abs(y))
    alb = np.where(border < 0.6, 0.3 if not white_markers else 0.15, alb)
    return alb.astype(np.float32)


def make_atlas(rng: np.random.Generator, white_markers: bool, avoid_uv: np.ndarray) -> Atlas:
    """Build the albedo atlas of a take.

    Parameters
    ----------
    rng : numpy.random.Generator
    white_markers : bool
        White markers take a black brim plate (and the other way round).
    avoid_uv : ndarray, shape (N, 2)
        Skin parameters of the markers, kept clear of moles.
    """
    img = np.full((_ATLAS_H, _ATLAS_W), 0.05, np.float32)

    def put(name, tex):
        x0, y0 = _ORIGIN[name]
        img[y0:y0 + tex.shape[0], x0:x0 + tex.shape[1]] = tex

    put("face", _face_texture(rng, avoid_uv))
    put("lid_L", _lid_texture(rng))
    put("lid_R", _lid_texture(rng))
    put("band", _band_texture(rng))
    put("brim", _brim_texture(rng, white_markers))
    bx, by = _ORIGIN["bg"]
    img[by:by + 8, bx:bx + 8] = 0.05
    return Atlas(np.clip(img, 0.0, 1.0))
