"""The synthetic face: a parametric skin surface, eyelids and blendshape-like expressions.

Head coordinates (millimetres), the frame the face is built in:

* ``X`` to the right in the cameras' images (the subject's left), ``Y`` down,
  ``Z`` away from the cameras, into the head.  The cheek plane is near ``Z = 0``;
  the nose tip sticks out to ``Z ~ -27``.
* The skin is a sheet parametrised by ``(u, v)``, its rest position in ``X, Y``
  (``u`` across, ``v`` down).  A point keeps its ``(u, v)`` however the face
  moves, so markers, texture and mesh all refer to the same parameters.

Expressions are additive displacement fields (one per blendshape, smooth in
``u, v``) plus a jaw rotation about the temporomandibular axis applied to the
lower face.  The lips meet along ``v = MOUTH_V``; a thin band of the sheet
around that line is folded into the mouth at rest (invisible) and stretches
into a dark mouth with teeth when the jaw opens.  The upper eyelids are
separate sheets in front of the eyes (see :func:`eyelid_params`): when they
close they cover the lower-lid margin, which hides the markers painted there.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "EXPRESSIONS", "MOUTH_V", "MOUTH_HALF", "EYE_U", "EYE_V", "EYE_HALF",
    "FaceBasis", "rest_depth", "eye_margins", "hairline", "inside_face", "jaw_weight",
    "eyelid_params", "EYELID_A", "EYELID_T_MM", "FACE_U", "FACE_V",
]

#: Expression channels, in the order of the weight vectors.  All weights are in 0..1.
EXPRESSIONS = ("jaw_open", "smile_L", "smile_R", "brow_raise_L", "brow_raise_R", "brow_furrow",
               "lip_curl", "pucker", "cheek_puff", "blink_L", "blink_R")
_ADDITIVE = ("smile_L", "smile_R", "brow_raise_L", "brow_raise_R", "brow_furrow", "lip_curl",
             "pucker", "cheek_puff", "blink_L", "blink_R")

# Landmarks of the rest face (mm).
MOUTH_V = 27.0          # where the lips meet
MOUTH_HALF = 26.0       # half-width of the mouth (corner at |u| = MOUTH_HALF)
BAND = 1.0              # half-height (in v) of the lip band folded into the mouth
EYE_U = 32.0            # eye centres at (+-EYE_U, EYE_V)
EYE_V = -33.0
EYE_HALF = 13.0         # half-width of the eye opening
FACE_U = (-74.0, 74.0)  # parameter domain of the skin sheet
FACE_V = (-104.0, 98.0)

# Jaw: rotation about the X axis through this (Y, Z) point (in front of the ears).
_JAW_HINGE = np.array([-8.0, 88.0])
_JAW_MAX_DEG = 17.0

# Eyelid sheets: parameter a in [-EYELID_A, EYELID_A] across the eye (1 = corner),
# t in [0, 1] from the crease to the lid margin.
EYELID_A = 1.12
EYELID_T_MM = 12.0     # texture scale of t (mm of lid per unit t), for texturing and markers
_LID_OVERLAP = 4.2     # how far past the lower-lid margin a fully closed lid reaches (mm)
_LID_THICK = 1.8       # how far the lid stands in front of the eyeball / lower lid (mm)


def _g(x):
    return np.exp(-0.5 * x * x)


def _smoothstep(e0, e1, x):
    t = np.clip((np.asarray(x, dtype=np.float64) - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def hairline(u):
    """``v`` of the hairline at ``u``: hair above (smaller v), forehead below."""
    u = np.asarray(u, dtype=np.float64)
    return -84.0 + 0.0062 * u * u


def inside_face(u, v):
    """True where the skin sheet exists (an oval a little larger than the face)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    return (u / 75.0) ** 2 + ((v + 3.0) / 103.0) ** 2 <= 1.0


def eye_margins(u, side: int):
    """Upper margin, lower margin and crease (``v``) of one eye at ``u``.

    ``side`` is +1 for the left eye (``u > 0``), -1 for the right.  The margins
    meet at the corners ``|u - side * EYE_U| = EYE_HALF``; outside they coincide.
    """
    x = (np.asarray(u, dtype=np.float64) - side * EYE_U) / EYE_HALF
    w = np.clip(1.0 - x * x, 0.0, None)
    # The upper margin peaks a little towards the nose, as real eyes do.
    up = EYE_V - 4.9 * w ** 0.75 * (1.0 - 0.12 * side * x)
    lo = EYE_V + 3.3 * w ** 0.9
    crease = EYE_V - 1.0 - 9.0 * w ** 0.5
    return up, lo, crease


def _nose(u, v):
    """Height (towards the camera, mm) of the nose above the base surface."""
    # Bridge to tip: grows from 6 mm to 26 mm, then drops under the tip to the lip.
    h_up = 5.5 + 20.5 * _smoothstep(-42.0, -3.0, v) ** 1.6
    h = np.where(v <= -3.0, h_up, 26.0 - 21.0 * _smoothstep(-3.0, 9.0, v) ** 0.8)
    h *= _smoothstep(-52.0, -36.0, v) * (1.0 - _smoothstep(9.0, 16.0, v))
    w = 5.5 + 6.5 * _smoothstep(-30.0, 2.0, v)
    z = -h * _g(u / w)
    # The alae (nostril wings).
    z -= 6.0 * _g((np.abs(u) - 13.5) / 4.8) * _g((v - 2.0) / 4.5)
    return z


def rest_depth(u, v):
    """Rest ``Z`` of the skin at parameters ``(u, v)`` (mm, smaller is nearer the cameras)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    rx, ry = 82.0, 190.0
    z = rx - np.sqrt(np.clip(rx * rx - u * u, 1.0, None))
    z += ry - np.sqrt(np.clip(ry * ry - (v + 5.0) ** 2, 1.0, None))
    au = np.abs(u)
    # Brow ridge, eye sockets with the eyeballs in them, cheekbones.
    z -= 4.0 * _g((v + 47.0) / 7.0) * np.exp(-0.5 * (u / 46.0) ** 4)
    z += 7.5 * _g((au - EYE_U) / 12.0) * _g((v - EYE_V) / 8.5)
    z -= 3.4 * _g((au - EYE_U) / 7.5) * _g((v - EYE_V) / 5.2)
    z -= 4.5 * _g((au - 40.0) / 13.0) * _g((v + 8.0) / 11.0)
    z += _nose(u, v)
    # Lips, the philtrum between nose and upper lip, the mouth corners, the chin.
    z -= 6.5 * np.exp(-0.5 * (u / 20.0) ** 4) * _g((v - 22.5) / 5.0)
    z -= 5.5 * np.exp(-0.5 * (u / 19.0) ** 4) * _g((v - 31.5) / 4.0)
    z += 1.0 * _g(u / 2.5) * _g((v - 16.0) / 3.0)
    z += 2.0 * _g((au - MOUTH_HALF) / 4.0) * _g((v - MOUTH_V) / 4.0)
    z -= 6.5 * _g(u / 17.0) * _g((v - 62.0) / 11.0)
    return z


def _band(u, v):
    """Lip-band coordinate ``s = (v - MOUTH_V) / BAND`` (|s| <= 1 in the band) and its taper to the corners."""
    s = (v - MOUTH_V) / BAND
    taper = np.clip(1.0 - (u / MOUTH_HALF) ** 2, 0.0, None) * (np.abs(s) < 1.0)
    return s, taper


def jaw_weight(u, v):
    """How much of the jaw rotation a skin point follows (0 above the mouth, 1 on the chin)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    # Between the lips the whole lip band opens: its upper edge stays with the
    # upper lip, its lower edge goes with the jaw, and the band (the mouth's
    # inside) spreads evenly between them.  On the cheeks beside the mouth the
    # skin stretches over a few centimetres.
    sharp = np.clip((v - (MOUTH_V - BAND)) / (2.0 * BAND), 0.0, 1.0)
    soft = _smoothstep(8.0, 52.0, v)
    m = _smoothstep(MOUTH_HALF - 4.0, MOUTH_HALF + 10.0, np.abs(u))
    return sharp * (1.0 - m) + soft * m


def _displacements(u, v) -> np.ndarray:
    """Additive displacement fields, shape ``(len(_ADDITIVE), N, 3)``, in mm at weight 1."""
    n = u.shape[0]
    d = np.zeros((len(_ADDITIVE), n, 3))
    au, sg = np.abs(u), np.sign(u)
    for k, side in ((0, 1.0), (1, -1.0)):                       # smiles
        su = side * u
        g1 = _g((su - MOUTH_HALF) / 13.0) * _g((v - MOUTH_V) / 11.0)
        g2 = _g((su - 36.0) / 15.0) * _g((v - 5.0) / 13.0)
        g3 = _g((su - EYE_U) / 12.0) * _g((v - EYE_V - 6.0) / 4.0)
        d[k, :, 0] = side * 5.5 * g1 + side * 1.0 * g2
        d[k, :, 1] = -5.0 * g1 - 3.5 * g2 - 1.5 * g3
        d[k, :, 2] = -1.0 * g1 - 3.0 * g2 - 0.5 * g3
    for k, side in ((2, 1.0), (3, -1.0)):                       # brow raises
        su = side * u
        # The forehead and brow move; the effect fades out above the eye opening.
        g = _g((su - 30.0) / 22.0) * _g((v + 54.0) / 15.0) * _smoothstep(EYE_V - 3.0, EYE_V - 9.0, v)
        d[k, :, 1] = -7.0 * g
        d[k, :, 2] = 0.6 * g
    g = _g((au - 15.0) / 11.0) * _g((v + 47.0) / 9.0)         # brow furrow
    d[4, :, 0] = -sg * 3.5 * g
    d[4, :, 1] = 3.5 * g
    d[4, :, 2] = -1.5 * g
    # Lip curl: the upper lip everts, its edge rolling forward and up (baring the
    # teeth), while the lower lip draws back.  Cameras above then look down over
    # the rolled lip onto the lower lip and lose its top; cameras below see under it.
    # (Zero beyond the mouth corners, where no lip band takes up the step between the lips.)
    gu = _g(u / 15.0) * (1.0 - _smoothstep(MOUTH_HALF - 8.0, MOUTH_HALF, au))
    up = np.clip((v - 12.0) / (MOUTH_V - 12.0), 0.0, 1.0) ** 2 * (v <= MOUTH_V)
    lo = _g((v - 30.5) / 4.5) * (v > MOUTH_V)
    d[5, :, 1] = gu * (-2.0 * up + 0.5 * lo)
    d[5, :, 2] = gu * (-13.0 * up + 3.5 * lo)
    g = _g(u / 22.0) * _g((v - MOUTH_V) / 9.0)                # pucker
    d[6, :, 0] = -0.35 * u * g
    d[6, :, 2] = -6.0 * g
    g = _g((au - 38.0) / 14.0) * _g((v - 22.0) / 14.0)        # cheek puff
    d[7, :, 0] = sg * 2.0 * g
    d[7, :, 2] = -6.0 * g
    for k, side in ((8, 1.0), (9, -1.0)):                       # blinks: brow and cheek follow a little
        su = side * u
        g = _g((su - EYE_U) / 16.0) * _g((v - EYE_V) / 12.0)
        d[k, :, 1] = -0.8 * g * np.tanh((v - EYE_V) / 3.0)
    return d


class FaceBasis:
    """The skin surface at fixed parameters, ready to be posed per frame.

    Parameters
    ----------
    u, v : array_like, shape (N,)
        Skin parameters (mm).

    Notes
    -----
    The rest positions, displacement fields and jaw weights are computed once;
    :meth:`pose` is then a small matrix product per frame.
    """

    def __init__(self, u, v):
        self.u = np.asarray(u, dtype=np.float64).ravel()
        self.v = np.asarray(v, dtype=np.float64).ravel()
        u, v = self.u, self.v
        z = rest_depth(u, v)
        s, taper = _band(u, v)
        # At rest the band is squeezed to the lip line and folded into the mouth.
        y = v - (v - MOUTH_V) * 0.985 * taper
        z = z + 8.0 * taper * (1.0 - s * s)
        self.rest = np.stack([u, y, z], axis=1)
        self.disp = _displacements(u, v)
        self.jaw = jaw_weight(u, v)

    def pose(self, weights) -> np.ndarray:
        """Positions (head coordinates, mm) under expression ``weights``.

        Parameters
        ----------
        weights : array_like, shape (len(EXPRESSIONS),)

        Returns
        -------
        ndarray, shape (N, 3)
        """
        w = np.asarray(weights, dtype=np.float64)
        add = np.array([w[EXPRESSIONS.index(n)] for n in _ADDITIVE])
        p = self.rest + np.tensordot(add, self.disp, axes=1)
        th = np.radians(_JAW_MAX_DEG) * w[0] * self.jaw
        if np.any(th):
            c, s = np.cos(th), np.sin(th)
            yz = p[:, 1:] - _JAW_HINGE
            p = p.copy()
            p[:, 1] = _JAW_HINGE[0] + c * yz[:, 0] - s * yz[:, 1]
            p[:, 2] = _JAW_HINGE[1] + s * yz[:, 0] + c * yz[:, 1]
            # The jaw also slides forward a little as it opens.
            p[:, 2] -= 2.0 * w[0] * self.jaw
        return p


def eyelid_params(side: int, a, t, closure: float):
    """Skin parameters ``(u, v)`` under eyelid point ``(a, t)`` and its stand-off from the skin.

    Parameters
    ----------
    side : {+1, -1}
        Left (+1) or right (-1) eye.
    a, t : array_like
        Across the eye (-1..1 corner to corner, a little beyond) and crease (0)
        to margin (1).
    closure : float
        0 open, 1 closed (the margin then reaches ``_LID_OVERLAP`` mm below the
        lower-lid margin).

    Returns
    -------
    u, v : ndarray
        The skin point the lid lies over.
    offset : ndarray
        Distance (mm) of the lid in front of the skin there.
    """
    a = np.asarray(a, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    u = side * EYE_U + side * a * EYE_HALF
    up, lo, crease = eye_margins(u, side)
    w = np.clip(1.0 - a * a, 0.0, None)
    margin = up + closure * (lo + _LID_OVERLAP * w ** 0.5 - up)
    v = crease + t * (margin - crease)
    offset = _LID_THICK * _smoothstep(0.0, 0.35, t) * (1.0 - _smoothstep(0.8, EYELID_A, np.abs(a)))
    return u, v, offset
