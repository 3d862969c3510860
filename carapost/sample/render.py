"""Draw one camera's image of one frame, and what of the markers it shows.

The surfaces (skin, lip band, eyelids, brim plate) are rasterised with a depth
buffer at a third of the resolution for the default 1280 px images (they are
smooth; their texture is still sampled per full-resolution pixel, and the
staircases along their outlines are softened); the painted dots
are added at full resolution with exact area coverage (:mod:`.coverage`), each
the ellipse of its disc's projected outline (same centroid and second moments):
as through a real lens, a dot's image is centred a little off the projection of
its centre, towards its nearer side (:mod:`carapost.core.disc_image`).  Without
the scene's ``perspective_dots`` each is the image of its disc under the
projection's linear map at its centre, centred on the projection (the takes of
carapost before session 24).  Lighting is the
helmet's: an LED ring beside each lens, falling off with distance, with a skin
sheen and glints on the corneas.  Then optical blur, then sensor noise.

A marker counts as *visible* in a camera when it faces the camera, lies wholly
in the image and nothing covers it: its centre and 8 points on a ring of 1.3
radii around it all see their own surface point in the depth buffer.  Markers
partly covered (by the curled lip, the closing eyelid, the nose) are drawn
clipped to their own surface and counted as *drawn* but not visible; markers
wholly covered are not drawn at all.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from carapost.core.camera import Camera
from carapost.core.disc_image import outline_moments

from .coverage import ellipse_coverage
from .face import EYE_HALF, EYE_U, EYE_V, eye_margins
from .raster import interpolate, rasterize
from .scene import SURF_BRIM, FrameGeometry, Scene, rng_for
from .texture import Atlas

__all__ = ["ViewTruth", "render_view", "leds_of", "EXPOSURE"]

EXPOSURE = 1.09          # grey level per unit radiance / 255: lit skin ~150, black paint ~10
_AMBIENT = 0.06
_LED_W = 0.4             # each of the 4 LED rings, at _D0 mm, facing the surface
_D0 = 150.0
_SHEEN = (0.05, 30.0)    # skin specular strength and exponent
_BG_SHADE = 0.35
_BG_ALBEDO = 0.05        # the helmet's inside, beyond the face (the atlas's background texel)
_VIS_TOL_MM = 0.8        # a ring point sees its own surface when the visible parameter is this close
_DEPTH_TOL_MM = 0.4      # ... or when nothing is nearer the camera than it by more than this (plus slope)
_MIN_COS = 0.15          # markers seen more obliquely than ~81 degrees are not counted as visible
_IRIS_R, _PUPIL_R = 5.8, 2.0
_OUTLINE = 96            # points on each dot's projected outline (its moments to well under 0.01 px)


@dataclass
class ViewTruth:
    """What one image shows of the markers (face markers first, then the brim's).

    Attributes
    ----------
    uv : ndarray, shape (P, 2)
        Raw-pixel projection of each marker's 3D centre (NaN behind the camera).
    centre : ndarray, shape (P, 2)
        Raw-pixel centre of each marker's image (what a blob detector should find): off ``uv`` by the
        perspective offset, a few hundredths of a pixel.
    visible : ndarray of bool, shape (P,)
        Drawn whole and unoccluded, facing the camera, inside the image.
    drawn : ndarray of bool, shape (P,)
        At least partly drawn.
    cos : ndarray, shape (P,)
        Cosine between the disc's normal and the direction to the camera.
    axes : ndarray, shape (P, 2)
        Semi-axes (major, minor) of the projected disc, pixels.
    """

    uv: np.ndarray
    centre: np.ndarray
    visible: np.ndarray
    drawn: np.ndarray
    cos: np.ndarray
    axes: np.ndarray


def leds_of(cameras: list[Camera]) -> np.ndarray:
    """LED ring positions (world mm): 12 mm below each lens."""
    return np.array([c.position + c.rotation.T @ np.array([0.0, 12.0, 0.0]) for c in cameras])


def _unit(a):
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    return a / np.where(n > 0, n, 1.0)


def _shade(points: np.ndarray, normals: np.ndarray, cam_pos: np.ndarray, leds: np.ndarray,
           sheen: np.ndarray) -> np.ndarray:
    """Radiance factor per point: ambient + Lambert from each LED (inverse square) + a sheen."""
    p = points.astype(np.float32)
    n = normals.astype(np.float32)
    d = leds.astype(np.float32)[:, None, :] - p[None]               # (L, V, 3)
    dist2 = np.einsum("lvk,lvk->lv", d, d)
    inv = 1.0 / np.sqrt(dist2)
    ndl = np.einsum("vk,lvk->lv", n, d) * inv
    fall = np.float32(_D0 * _D0) / dist2
    lit = np.clip(ndl, 0.0, None) * fall
    out = _AMBIENT + _LED_W * lit.sum(axis=0)
    # Sheen: Blinn-Phong towards this camera.
    view = cam_pos.astype(np.float32) - p
    view *= 1.0 / np.linalg.norm(view, axis=1, keepdims=True)
    h = d * inv[..., None] + view[None]
    ndh = np.clip(np.einsum("vk,lvk->lv", n, h) / np.linalg.norm(h, axis=2), 0.0, None)
    ks, alpha = _SHEEN
    out += sheen * ks * np.sum(ndh ** alpha * fall * (ndl > 0), axis=0)
    return out


@lru_cache(maxsize=8)
def _vignette(width: int, height: int, cx: float, cy: float) -> np.ndarray:
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / float(width * width / 4 + height * height / 4)
    return (1.0 - 0.32 * r2).astype(np.float32)


def _sample_raster(surf_r, param_r, xy_r):
    """Surface id and bilinear parameters at raster points; id -2 where the 4 neighbours disagree.

    ``param_r`` is planar, shape (2, Hr, Wr).
    """
    Hr, Wr = surf_r.shape
    x, y = xy_r[..., 0], xy_r[..., 1]
    ok = np.isfinite(x) & np.isfinite(y)
    x = np.where(ok, x, -10.0)
    y = np.where(ok, y, -10.0)
    j0 = np.floor(x).astype(np.int64)
    i0 = np.floor(y).astype(np.int64)
    ok &= (j0 >= 0) & (i0 >= 0) & (j0 + 1 < Wr) & (i0 + 1 < Hr)
    j0 = np.where(ok, j0, 0)
    i0 = np.where(ok, i0, 0)
    fx = x - j0
    fy = y - i0
    s00, s01 = surf_r[i0, j0], surf_r[i0, j0 + 1]
    s10, s11 = surf_r[i0 + 1, j0], surf_r[i0 + 1, j0 + 1]
    same = ok & (s00 == s01) & (s00 == s10) & (s00 == s11)
    p = np.stack([pr[i0, j0] * (1 - fx) * (1 - fy) + pr[i0, j0 + 1] * fx * (1 - fy)
                  + pr[i0 + 1, j0] * (1 - fx) * fy + pr[i0 + 1, j0 + 1] * fx * fy for pr in param_r], axis=-1)
    return np.where(same, s00, -2), p


def _blend_markers(albedo: np.ndarray, x0, y0, cov, paint) -> None:
    """Paint the markers into the albedo in place: ``albedo (1 - c) + paint c`` per pixel.

    Coverage of every box is summed per pixel (boxes overlap; the discs do not),
    only over the pixels the discs touch.
    """
    H, W = albedo.shape
    M, n, _ = cov.shape
    yy = y0[:, None, None] + np.arange(n)[None, :, None]
    xx = x0[:, None, None] + np.arange(n)[None, None, :]
    ok = (cov > 0) & (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
    if not np.any(ok):
        return
    flat = (yy * W + xx)[ok]
    c = cov[ok].astype(np.float64)
    cp = (cov * np.asarray(paint, np.float32)[:, None, None])[ok].astype(np.float64)
    pix, inv = np.unique(flat, return_inverse=True)
    C = np.bincount(inv, weights=c, minlength=pix.size)
    CP = np.bincount(inv, weights=cp, minlength=pix.size)
    over = C > 1.0
    CP[over] /= C[over]
    C[over] = 1.0
    a = albedo.reshape(-1)
    a[pix] = a[pix] * (1.0 - C) + CP


def _min_depth(depth_r, xy_r) -> np.ndarray:
    """Nearest depth among the 4 raster pixels around each point (-inf outside the raster)."""
    Hr, Wr = depth_r.shape
    x = np.nan_to_num(xy_r[..., 0], nan=-10.0)
    y = np.nan_to_num(xy_r[..., 1], nan=-10.0)
    j0 = np.floor(x).astype(np.int64)
    i0 = np.floor(y).astype(np.int64)
    ok = (j0 >= 0) & (i0 >= 0) & (j0 + 1 < Wr) & (i0 + 1 < Hr)
    j0 = np.where(ok, j0, 0)
    i0 = np.where(ok, i0, 0)
    d = np.minimum(np.minimum(depth_r[i0, j0], depth_r[i0, j0 + 1]),
                   np.minimum(depth_r[i0 + 1, j0], depth_r[i0 + 1, j0 + 1]))
    return np.where(ok, d, -np.inf)


def _jacobians(cam: Camera, g: FrameGeometry) -> np.ndarray:
    """d(raw pixel) / d(disc coordinates) at each marker centre, times its radius: (P, 2, 2)."""
    h = 0.02
    p = g.points
    cols = []
    for k in range(2):
        e = g.axes[:, k]
        cols.append((cam.project(p + h * e) - cam.project(p - h * e)) / (2 * h))
    return np.stack(cols, axis=-1) * g.radius[:, None, None]


def _dot_images(cam: Camera, g: FrameGeometry):
    """Each disc's image as an ellipse: centre (P, 2), the linear map of the unit circle onto it (P, 2, 2)
    and its semi-axes (P, 2), major first; raw pixels, NaN where it does not project."""
    centre, cov = outline_moments(cam.project, g.points, g.radius, g.axes[:, 0], g.axes[:, 1], n=_OUTLINE,
                                  second=True)
    w, v = np.linalg.eigh(np.nan_to_num(cov))
    # A uniform ellipse's variance is a**2 / 4; a dot seen exactly edge-on keeps a sliver (coverage inverts the map).
    semi = np.maximum(2.0 * np.sqrt(np.maximum(w, 0.0)), 1e-3)
    return centre, v * semi[:, None, :], semi[:, ::-1]


def _draw_eyes(albedo, surf_r, A, k: int, gaze, origin) -> None:
    """The irises and pupils (they move, so they are not in the texture).

    ``albedo`` is the full-resolution window whose top-left raster pixel is ``origin``.
    """
    near = (surf_r == 0) & (np.abs(A[3] - EYE_V) < 7.0)
    for side in (1, -1):
        ys, xs = np.nonzero(near & (np.abs(A[2] - side * EYE_U) < EYE_HALF))
        if ys.size == 0:
            continue
        # A raster window around the eye with a margin, upsampled like the whole image.
        # (Clipped to the albedo window, which holds every surface pixel.)
        r0, r1 = max(ys.min() - 3, origin[0]), min(ys.max() + 4, origin[0] + albedo.shape[0] // k)
        c0, c1 = max(xs.min() - 3, origin[1]), min(xs.max() + 4, origin[1] + albedo.shape[1] // k)
        par = cv2.merge([A[2, r0:r1, c0:c1], A[3, r0:r1, c0:c1]])
        sr = surf_r[r0:r1, c0:c1]
        if k > 1:
            par = cv2.resize(par, ((c1 - c0) * k, (r1 - r0) * k), interpolation=cv2.INTER_LINEAR)
            sr = np.repeat(np.repeat(sr, k, axis=0), k, axis=1)
        pu, pv = par[..., 0], par[..., 1]
        a = albedo[(r0 - origin[0]) * k:(r1 - origin[0]) * k, (c0 - origin[1]) * k:(c1 - origin[1]) * k]
        up, lo, _ = eye_margins(pu, side)
        x = (pu - side * EYE_U) / EYE_HALF
        m = (sr == 0) & (np.abs(x) < 1.0) & (pv > up - 0.3) & (pv < lo + 0.3)
        if not np.any(m):
            continue
        du = pu[m] - (side * EYE_U + gaze[0])
        dv = pv[m] - (EYE_V + 0.4 + gaze[1])
        rho = np.hypot(du, dv)
        th = np.arctan2(dv, du)
        iris = 0.25 + 0.035 * np.cos(19.0 * th + 1.3 * side) * (rho / _IRIS_R) - 0.07 * np.clip(
            (rho - 0.85 * _IRIS_R) / (0.15 * _IRIS_R), 0.0, 1.0)
        mi = np.clip((_IRIS_R - rho) / 0.3 + 0.5, 0.0, 1.0)
        mp = np.clip((_PUPIL_R - rho) / 0.25 + 0.5, 0.0, 1.0)
        val = iris * (1 - mp) + 0.04 * mp
        a[m] = a[m] * (1 - mi) + val * mi


def render_view(scene: Scene, g: FrameGeometry, cam: Camera, c: int, f: int, *, leds: np.ndarray | None = None,
                noise: float | None = None, blur: float | None = None, markers: bool = True,
                as_float: bool = False):
    """Render camera ``c``'s image of frame ``f``.

    Parameters
    ----------
    scene : Scene
    g : FrameGeometry
        ``frame_geometry(scene, f)``.
    cam : Camera
        The true camera ``c`` on frame ``f``.
    c, f : int
        Camera and frame (gain, noise stream).
    leds : ndarray, shape (L, 3), optional
        LED positions.  All four LED rings light every image: pass
        ``leds_of(true_cameras(scene, f))``; by default only this camera's own ring.
    noise, blur : float, optional
        Override the scene's sensor noise (grey levels) and blur (px); 0 turns them off.
    markers : bool
        Draw the painted markers (False: the same image without them).
    as_float : bool
        Return the float image before quantisation (for tests).

    Returns
    -------
    image : ndarray, (H, W) uint8 (float32 with ``as_float``)
    truth : ViewTruth
    """
    W, H = scene.width, scene.height
    k = scene.raster_scale
    Wr, Hr = W // k, H // k
    mesh = scene.mesh
    noise = scene.noise if noise is None else float(noise)
    blur = scene.blur if blur is None else float(blur)
    if leds is None:
        leds = leds_of([cam])

    # ---- surfaces, at raster resolution
    raw = cam.project(g.verts)
    depth = cam.depth(g.verts)
    xr = (raw + 0.5) / k - 0.5
    tri_map, bary = rasterize(xr, depth, mesh.tris, Wr, Hr)
    sheen = (mesh.surf != SURF_BRIM).astype(np.float64) + 0.3 * (mesh.surf == SURF_BRIM)
    shade_v = _shade(g.verts, g.normals, cam.position, leds, sheen)
    attrs = np.vstack([mesh.atlas_T, mesh.param_T, shade_v[None].astype(np.float32), depth[None].astype(np.float32)])
    bgx, bgy = Atlas.background()
    A = interpolate(tri_map, bary, mesh.tris, attrs, (bgx, bgy, 0.0, 0.0, _BG_SHADE, 1e9))
    surf_r = np.where(tri_map >= 0, mesh.tri_surf[np.maximum(tri_map, 0)], -1).astype(np.int8)

    # ---- marker visibility (against the raster)
    uv = cam.project(g.points)
    ring_uv = cam.project(g.ring)
    view = g.points - cam.position
    cosv = -np.einsum("ij,ij->i", g.normal, _unit(view))
    ring_r = (ring_uv + 0.5) / k - 0.5
    s_ring, p_ring = _sample_raster(surf_r, A[2:4], ring_r)
    own = (s_ring == g.surf[:, None]) & (np.linalg.norm(p_ring - g.ring_param, axis=-1) < _VIS_TOL_MM)
    # Or nothing nearer than the point itself: the nearest depth around it is not
    # in front by more than the surface's own slope across the lookup (grazing
    # views of the marker's own surface, e.g. over the lip edge).
    footprint = k * cam.depth(g.points) / cam.focal_length                       # mm per raster pixel
    tan = np.sqrt(np.clip(1.0 - cosv ** 2, 0.0, None)) / np.clip(np.abs(cosv), 0.25, None)
    tol = _DEPTH_TOL_MM + 1.5 * footprint * tan
    own |= cam.depth(g.ring) <= _min_depth(A[5], ring_r) + tol[:, None]
    n_own = own.sum(axis=1)
    inside = np.all((ring_uv[..., 0] >= 1) & (ring_uv[..., 0] <= W - 2) & (ring_uv[..., 1] >= 1)
                    & (ring_uv[..., 1] <= H - 2), axis=1)
    facing = (cosv > 0) & np.all(np.isfinite(uv), axis=1)
    visible = facing & (n_own == 9) & inside & (cosv >= _MIN_COS)
    drawn = facing & (n_own >= 1)
    if scene.perspective_dots:
        centre, J, sv = _dot_images(cam, g)
    else:
        J = _jacobians(cam, g)
        sv = np.linalg.svd(np.nan_to_num(J), compute_uv=False)
        centre = uv
    truth = ViewTruth(uv=uv, centre=centre, visible=visible, drawn=drawn, cos=cosv, axes=sv)

    # ---- full resolution, in a window around the surfaces (the rest is background)
    wy0, wy1, wx0, wx1 = _window(tri_map, k, blur)
    r0, r1, c0, c1 = wy0 // k, wy1 // k, wx0 // k, wx1 // k
    tex = cv2.merge([A[0, r0:r1, c0:c1], A[1, r0:r1, c0:c1], A[4, r0:r1, c0:c1]])
    if k > 1:
        T = cv2.resize(tex, ((c1 - c0) * k, (r1 - r0) * k), interpolation=cv2.INTER_LINEAR)
        # Across surface boundaries and silhouettes, interpolated texture
        # coordinates would be meaningless: take the nearest raster pixel there.
        kern = np.ones((3, 3), np.uint8)
        su = (surf_r[r0:r1, c0:c1] + 2).astype(np.uint8)
        edge = cv2.dilate(su, kern) != cv2.erode(su, kern)
        for ch in (2, 3):
            p = A[ch, r0:r1, c0:c1]
            edge |= (cv2.dilate(p, kern) - cv2.erode(p, kern)) > 3.0
        size = ((c1 - c0) * k, (r1 - r0) * k)
        edge_f = cv2.resize(edge.view(np.uint8), size, interpolation=cv2.INTER_NEAREST).view(bool)
        np.copyto(T, cv2.resize(tex, size, interpolation=cv2.INTER_NEAREST), where=edge_f[..., None])
    else:
        T = tex
        edge_f = None
    albedo = cv2.remap(scene.atlas.image, T[..., 0], T[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    _draw_eyes(albedo, surf_r, A, k, scene.motion.gaze[f], (r0, c0))
    shade = np.ascontiguousarray(T[..., 2])
    if edge_f is not None:
        # Those edges are staircases of raster pixels: soften them (the dots,
        # drawn next, keep their exact coverage).
        for a in (albedo, shade):
            np.copyto(a, cv2.blur(a, (2 * k + 1, 2 * k + 1)), where=edge_f)

    # ---- painted markers, exact coverage, blended into the albedo
    if markers and np.any(drawn):
        idx = np.flatnonzero(drawn)
        x0, y0, cov = ellipse_coverage(centre[idx], J[idx])
        part = np.flatnonzero(n_own[idx] < 9)
        if part.size:
            # Partly covered: keep only pixels that show the marker's own surface near it
            # (looked up in the raster, nearest pixel).
            n = cov.shape[1]
            yy = np.clip(y0[part, None, None] + np.arange(n)[None, :, None], 0, H - 1) // k
            xx = np.clip(x0[part, None, None] + np.arange(n)[None, None, :], 0, W - 1) // k
            pp = np.stack([A[2, yy, xx], A[3, yy, xx]], axis=-1)
            lim = 1.6 * g.radius[idx[part]] + 1.0
            mine = (surf_r[yy, xx] == g.surf[idx[part], None, None]) & (
                np.linalg.norm(pp - g.param[idx[part], None, None, :], axis=-1) < lim[:, None, None])
            cov[part] *= mine
        _blend_markers(albedo, x0 - wx0, y0 - wy0, cov, scene.paint[idx])

    # ---- light, glints, optics, sensor
    gain = EXPOSURE * 255.0 * float(scene.motion.gain[f, c])
    vig = _vignette(W, H, float(cam.principal_point[0]), float(cam.principal_point[1]))
    win = cv2.multiply(shade, albedo, scale=gain)
    win *= vig[wy0:wy1, wx0:wx1]
    _glints(win, (wy0, wx0), g, cam, leds, surf_r, A, k)
    if blur > 0:
        # The window reaches 4 sigma into the background, so blurring it alone is
        # blurring the image.
        win = cv2.GaussianBlur(win, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
    img = vig * np.float32(gain * _BG_ALBEDO * _BG_SHADE)
    img[wy0:wy1, wx0:wx1] = win
    if noise > 0:
        img += noise * _noise_field(scene.seed, W, H, c, f)
    if as_float:
        return img, truth
    np.maximum(img, 0.0, out=img)
    return cv2.convertScaleAbs(img), truth       # rounds and saturates to 0..255


def _window(tri_map: np.ndarray, k: int, blur: float) -> tuple[int, int, int, int]:
    """Full-resolution rows and columns ``(y0, y1, x0, x1)`` that hold every surface, plus a blur margin.

    Multiples of ``k``, so that the window is whole raster pixels.
    """
    Hr, Wr = tri_map.shape
    hit = tri_map >= 0
    rows = np.flatnonzero(hit.any(axis=1))
    cols = np.flatnonzero(hit.any(axis=0))
    if rows.size == 0:
        return 0, k, 0, k
    m = int(np.ceil((4.0 * blur + 3.0) / k)) + 1
    r0, r1 = max(rows[0] - m, 0), min(rows[-1] + 1 + m, Hr)
    c0, c1 = max(cols[0] - m, 0), min(cols[-1] + 1 + m, Wr)
    return r0 * k, r1 * k, c0 * k, c1 * k


_BANK = 4
_PAD = 48


@lru_cache(maxsize=2)
def _noise_bank(seed: int, width: int, height: int) -> np.ndarray:
    """A few unit Gaussian noise fields, a little larger than the image."""
    rng = rng_for(seed, 101)
    return rng.standard_normal((_BANK, height + _PAD, width + _PAD), dtype=np.float32)


def _noise_field(seed: int, width: int, height: int, c: int, f: int) -> np.ndarray:
    """Unit Gaussian sensor noise for camera ``c``, frame ``f``: a random window of a noise bank.

    Drawing 0.9 million normals per image costs as much as rendering it; a
    window of a few stored fields at a random offset is just as white and
    independent-looking from frame to frame, and deterministic.
    """
    bank = _noise_bank(seed, width, height)
    i, dy, dx = rng_for(seed, 100, c, f).integers(0, [_BANK, _PAD + 1, _PAD + 1])
    return bank[i, dy:dy + height, dx:dx + width]


def _glints(img, origin, g: FrameGeometry, cam: Camera, leds, surf_r, A, k: int) -> None:
    """Specular reflections of the LEDs on the corneas: small bright spots (white-marker confusers).

    ``img`` is the full-resolution window whose top-left pixel is ``origin`` (y, x).
    """
    H, W = img.shape
    oy, ox = origin
    sigma = 0.55 * cam.sensor_size[0] / 1280.0 + 0.25
    r = int(np.ceil(3 * sigma))
    centre = np.repeat(g.eyes, len(leds), axis=0)                    # (2L, 3)
    led = np.tile(leds, (len(g.eyes), 1))
    to_led = led - centre
    dist = np.linalg.norm(to_led, axis=1)
    p = centre + 7.8 * _unit(_unit(cam.position - centre) + to_led / dist[:, None])
    Hr, Wr = surf_r.shape
    for (x, y), d in zip(cam.project(p), dist):
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        i, j = int(round(y)), int(round(x))
        if not (r <= i - oy < H - r - 1 and r <= j - ox < W - r - 1) or i // k >= Hr or j // k >= Wr:
            continue
        # Only where the eye itself shows (not under the lid).
        pu, pv = A[2, i // k, j // k], A[3, i // k, j // k]
        side = 1 if pu > 0 else -1
        up, lo, _ = eye_margins(pu, side)
        if surf_r[i // k, j // k] != 0 or abs(pu - side * EYE_U) > EYE_HALF or not (up < pv < lo):
            continue
        yy, xx = np.mgrid[i - r:i + r + 1, j - r:j + r + 1]
        spot = np.exp(-0.5 * ((xx - x) ** 2 + (yy - y) ** 2) / sigma ** 2)
        img[i - oy - r:i - oy + r + 1, j - ox - r:j - ox + r + 1] += (160.0 * (_D0 / d) ** 2 * spot).astype(np.float32)
