"""Where the dots are painted: named anatomical landmarks, then an even fill.

A marker lives on a surface (the skin, or one of the two upper eyelids) at
fixed surface parameters, so it moves with the skin.  Labels are unique,
anatomical-ish names (``Brow_L_1``, ``Nose_Tip``, ``Lip_Upper_C`` ...); ``L``
is the subject's left, which is image right (``u > 0``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .face import (EYE_HALF, EYE_U, EYE_V, MOUTH_HALF, MOUTH_V, eye_margins, hairline, inside_face,
                   rest_depth)

__all__ = ["SURF_FACE", "SURF_LID_L", "SURF_LID_R", "MarkerSet", "layout_markers", "named_landmarks"]

SURF_FACE, SURF_LID_L, SURF_LID_R = 0, 1, 2

# Painted dot radius range (mm): ~3 mm dots, 9-12 px across in the default take.
_RADIUS_MM = (1.3, 1.6)


@dataclass
class MarkerSet:
    """The painted markers of a take.

    Attributes
    ----------
    labels : list of str
    surface : ndarray of int, shape (N,)
        ``SURF_FACE``, ``SURF_LID_L`` or ``SURF_LID_R``.
    p : ndarray, shape (N, 2)
        Surface parameters: ``(u, v)`` on the skin, ``(a, t)`` on an eyelid.
    radius : ndarray, shape (N,)
        Disc radius, mm.
    """

    labels: list
    surface: np.ndarray
    p: np.ndarray
    radius: np.ndarray

    def __len__(self) -> int:
        return len(self.labels)


def named_landmarks() -> list[tuple[str, int, float, float]]:
    """The named markers, most important first: ``(label, surface, p1, p2)``."""
    lo_l = float(eye_margins(EYE_U, 1)[1]) + 1.3     # just under the lower lash line
    out = [
        ("Nose_Tip", SURF_FACE, 0.0, -3.0),
        ("Nose_Bridge", SURF_FACE, 0.0, -32.0),
        ("Forehead_C", SURF_FACE, 0.0, -68.0),
        ("Chin_C", SURF_FACE, 0.0, 63.0),
        ("Lip_Upper_C", SURF_FACE, 0.0, 23.0),
        ("Lip_Lower_C", SURF_FACE, 0.0, 31.0),
    ]
    pairs = [
        ("Brow_{s}_1", SURF_FACE, 13.0, -45.5),
        ("Brow_{s}_2", SURF_FACE, 29.0, -50.5),
        ("Brow_{s}_3", SURF_FACE, 45.0, -47.5),
        ("Eyelid_{s}_Upper", None, 0.0, 0.62),
        ("Eyelid_{s}_Lower", SURF_FACE, EYE_U, lo_l),
        ("Mouth_Corner_{s}", SURF_FACE, MOUTH_HALF + 2.0, MOUTH_V + 0.5),
        ("Lip_Upper_{s}", SURF_FACE, 11.0, 23.6),
        ("Lip_Lower_{s}", SURF_FACE, 11.0, 30.6),
        ("Cheek_{s}_1", SURF_FACE, 41.0, -12.0),
        ("Cheek_{s}_2", SURF_FACE, 44.0, 10.0),
        ("Nostril_{s}", SURF_FACE, 14.5, -4.0),
        ("Nasolabial_{s}", SURF_FACE, 23.0, 13.0),
        ("Forehead_{s}_1", SURF_FACE, 26.0, -66.0),
        ("Jaw_{s}_1", SURF_FACE, 40.0, 52.0),
        ("Chin_{s}_1", SURF_FACE, 16.0, 55.0),
    ]
    for name, surf, p1, p2 in pairs:
        for s, sign, lid in (("L", 1.0, SURF_LID_L), ("R", -1.0, SURF_LID_R)):
            if surf is None:    # an eyelid marker: parameters (a, t) are the same on both lids
                out.append((name.format(s=s), lid, p1, p2))
            else:
                out.append((name.format(s=s), surf, sign * p1, p2))
    return out


def _allowed(u, v) -> np.ndarray:
    """Where fill markers may go: skin the cameras see well, away from eyes, nostrils, mouth, hair."""
    ok = inside_face(u * 75.0 / 64.0, (v + 3.0) * 103.0 / 92.0 - 3.0)
    ok &= v > np.maximum(hairline(u) + 7.0, -80.0)
    for side in (1.0, -1.0):
        # The eye and its upper lid, which reaches up to the crease ~10 mm above the eye.
        ok &= ((u - side * EYE_U) / (EYE_HALF + 5.0)) ** 2 + ((v - EYE_V + 1.5) / 13.0) ** 2 > 1.0
        ok &= ((u - side * 7.0) / 6.0) ** 2 + ((v - 4.0) / 5.0) ** 2 > 1.0     # nostrils
    ok &= ~((np.abs(u) < MOUTH_HALF + 4.0) & (np.abs(v - MOUTH_V) < 10.0))    # lips: named markers only
    # Not where the skin turns away from the cameras (sides of the nose tip, jaw line).
    h = 0.25
    gz = np.hypot((rest_depth(u + h, v) - rest_depth(u - h, v)) / (2 * h),
                  (rest_depth(u, v + h) - rest_depth(u, v - h)) / (2 * h))
    ok &= gz < 1.2
    return ok


def _region(u: float, v: float) -> str:
    side = "C" if abs(u) < 4.0 else ("L" if u > 0 else "R")
    au = abs(u)
    if v < -52.0:
        reg = "Temple" if au > 50 else "Forehead"
    elif v < -38.0:
        reg = "Temple" if au > 50 else ("Glabella" if au < 8 else "Brow")
    elif au < 11.0 and v < 8.0:
        reg = "Nose"
    elif v < -20.0:
        reg = "Temple" if au > 48 else "Eye_Socket"
    elif v < 18.0:
        reg = "Cheek" if au > 17 else "Upper_Lip"
    elif v < 40.0:
        reg = "Cheek" if au > 30 else "Lip_Area"
    else:
        reg = "Chin" if au < 24 else "Jaw"
    return f"{reg}_{side}"


def layout_markers(n: int, rng: np.random.Generator) -> MarkerSet:
    """Lay out ``n`` markers: the named landmarks first, then an even fill of the face.

    Parameters
    ----------
    n : int
        Number of markers (35 to 160 is the intended range; at least 1).
    rng : numpy.random.Generator
        Source of the fill positions and radii (the layout is a function of it).

    Returns
    -------
    MarkerSet
    """
    if n < 1:
        raise ValueError(f"a face needs at least one marker, not {n}")
    named = named_landmarks()[:n]
    labels = [m[0] for m in named]
    surface = [m[1] for m in named]
    # Nobody paints a dot exactly where the chart says: ~1 mm of scatter, a
    # tenth of that where the anatomy is tight (lids, lips, nostrils).
    tight = ("Eyelid", "Lip_", "Mouth_", "Nostril")
    pts = []
    for lab, surf, p1, p2 in named:
        sd = 0.0 if surf != SURF_FACE else (0.15 if lab.startswith(tight) else 1.0)
        du, dv = np.clip(rng.normal(0.0, sd, 2), -2.5 * sd, 2.5 * sd) if sd else (0.0, 0.0)
        pts.append((p1 + du, p2 + dv))
    need = n - len(named)
    if need > 0:
        # Dart throwing: random allowed points, accepted when far enough from
        # every marker so far; the spacing shrinks until enough fit.
        cand = np.column_stack([rng.uniform(-66, 66, 8000), rng.uniform(-80, 90, 8000)])
        frac = _allowed(cand[:, 0], cand[:, 1]).mean()
        cand = cand[_allowed(cand[:, 0], cand[:, 1])]
        fixed = np.array([p for p, s in zip(pts, surface) if s == SURF_FACE]).reshape(-1, 2)
        area = frac * 132.0 * 170.0
        d = 1.15 * np.sqrt(area / (need + len(fixed)))
        base = np.full(len(cand), np.inf)
        for q in fixed:
            base = np.minimum(base, np.hypot(*(cand - q).T))
        while True:
            mind = base.copy()
            chosen = []
            for i in range(len(cand)):
                if mind[i] >= d:
                    chosen.append(cand[i])
                    mind = np.minimum(mind, np.hypot(*(cand - cand[i]).T))
                    if len(chosen) == need:
                        break
            if len(chosen) == need:
                break
            d *= 0.94
        chosen = list(fixed) + chosen
        fill = np.array(chosen[len(fixed):])
        # Order the fill top to bottom, left to right, so labels read naturally.
        fill = fill[np.lexsort((fill[:, 0], np.round(fill[:, 1] / 8.0)))]
        counts: dict[str, int] = {}
        for lab in labels:
            parts = lab.rsplit("_", 1)
            if parts[-1].isdigit():
                counts[parts[0]] = max(counts.get(parts[0], 0), int(parts[-1]))
        for u, v in fill:
            reg = _region(float(u), float(v))
            counts[reg] = counts.get(reg, 0) + 1
            labels.append(f"{reg}_{counts[reg]}")
            surface.append(SURF_FACE)
            pts.append((float(u), float(v)))
    radius = rng.uniform(*_RADIUS_MM, n)
    return MarkerSet(labels, np.array(surface, dtype=np.int32), np.array(pts, dtype=np.float64), radius)
