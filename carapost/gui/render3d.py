"""Offscreen OpenGL rendering of the 3D view (Qt-free).

The 3D view needs an OpenGL context that exists everywhere carapost runs,
including headless machines (``QT_QPA_PLATFORM=offscreen``, CI), where a
``QOpenGLWidget`` gets none.  A standalone moderngl context on EGL (Mesa's
llvmpipe when there is no GPU) renders into its own framebuffer; the image is
read back as an RGBA numpy array that the widget paints and the tests inspect.

Conventions: world coordinates are the project's (mm, the brim's frame).  The
view camera is an orbit camera (:class:`OrbitCamera`) with an OpenGL view
frame (x right, y up, looking down -z); :meth:`OrbitCamera.project` maps world
points to widget pixels (x right, y down, pixel ``(c, r)`` centred on
``(c + 0.5, r + 0.5)``), exactly where :class:`Renderer` draws them.  The
projection matrix flips y so that row 0 of the framebuffer is the top row of
the image: the read-back needs no flip.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class RenderUnavailable(RuntimeError):
    """No OpenGL context could be created (no EGL, no driver)."""


# ---------------------------------------------------------------------------- camera
def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def _orthonormal(M: np.ndarray) -> np.ndarray:
    """The rotation nearest ``M``."""
    u, _s, vt = np.linalg.svd(M)
    R = u @ vt
    if np.linalg.det(R) < 0:
        u[:, -1] *= -1
        R = u @ vt
    return R


@dataclass
class OrbitCamera:
    """A perspective camera turning about a target point.

    Attributes
    ----------
    target : ndarray (3,)
        The point looked at and rotated about (mm).
    distance : float
        From the eye to the target (mm).
    rotation : ndarray (3, 3)
        World to view (rows: the view's x right, y up, z backwards).
    fov_y : float
        Vertical field of view in degrees.
    width, height : int
        Viewport size in pixels.
    """

    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance: float = 500.0
    rotation: np.ndarray = field(default_factory=lambda: np.diag([1.0, -1.0, -1.0]))
    fov_y: float = 35.0
    width: int = 640
    height: int = 480

    # ----------------------------------------------------------------- matrices
    @property
    def eye(self) -> np.ndarray:
        """Eye position in world mm."""
        return self.target + self.rotation[2] * self.distance

    def focal_px(self) -> float:
        """Focal length in pixels (vertical)."""
        return 0.5 * self.height / np.tan(np.deg2rad(self.fov_y) / 2)

    def view_matrix(self) -> np.ndarray:
        V = np.eye(4)
        V[:3, :3] = self.rotation
        V[:3, 3] = -self.rotation @ self.eye
        return V

    def clip_planes(self, radius: float) -> tuple[float, float]:
        """Near and far planes that hold a scene of ``radius`` mm around the target."""
        far = self.distance + max(radius, 1.0) * 4 + 10.0
        near = max(self.distance - max(radius, 1.0) * 4, far * 1e-4, 0.05)
        return near, far

    def projection_matrix(self, near: float, far: float) -> np.ndarray:
        """OpenGL perspective projection with y flipped (row 0 of the framebuffer is the top)."""
        f = 1.0 / np.tan(np.deg2rad(self.fov_y) / 2)
        aspect = self.width / max(self.height, 1)
        P = np.zeros((4, 4))
        P[0, 0] = f / aspect
        P[1, 1] = -f
        P[2, 2] = (far + near) / (near - far)
        P[2, 3] = 2 * far * near / (near - far)
        P[3, 2] = -1.0
        return P

    def to_view(self, X) -> np.ndarray:
        """View-frame coordinates of world points ``X`` (N, 3)."""
        return (np.asarray(X, float).reshape(-1, 3) - self.eye) @ self.rotation.T

    def project(self, X) -> np.ndarray:
        """Widget pixels (N, 2) of world points ``X`` (N, 3); NaN behind the eye or for NaN input."""
        Xv = self.to_view(X)
        z = -Xv[:, 2]
        fp = self.focal_px()
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.width / 2 + fp * Xv[:, 0] / z
            v = self.height / 2 - fp * Xv[:, 1] / z
        out = np.stack([u, v], axis=1)
        out[~(z > 0)] = np.nan
        return out

    # --------------------------------------------------------------- navigation
    def orbit(self, dx_px: float, dy_px: float) -> None:
        """Turn about the target: a drag across the view's width turns half a revolution."""
        k = np.pi / max(self.width, 1)
        self.rotation = _orthonormal(_rot(0, -dy_px * k) @ _rot(1, -dx_px * k) @ self.rotation)

    def zoom(self, factor: float) -> None:
        """Move the eye towards (``factor`` < 1) or away from the target."""
        self.distance = float(np.clip(self.distance * factor, 1.0, 1e6))

    def pan(self, dx_px: float, dy_px: float) -> None:
        """Truck the target with the mouse: the point under the cursor stays under it."""
        mm_per_px = self.distance / self.focal_px()
        self.target = self.target - self.rotation[0] * dx_px * mm_per_px + self.rotation[1] * dy_px * mm_per_px

    def center_on(self, X) -> bool:
        """Put the centre of points ``X`` at the middle of the view (same zoom); False when none."""
        X = _finite_rows(X)
        if not len(X):
            return False
        self.target = X.mean(axis=0)
        return True

    def frame(self, X, margin: float = 1.15, min_radius: float = 10.0) -> bool:
        """Centre on points ``X`` and move the eye so they fill the view; False when none."""
        X = _finite_rows(X)
        if not len(X):
            return False
        lo, hi = X.min(axis=0), X.max(axis=0)
        self.target = (lo + hi) / 2
        radius = max(float(np.linalg.norm(X - self.target, axis=1).max()), min_radius)
        half = np.deg2rad(self.fov_y) / 2
        half = min(half, np.arctan(np.tan(half) * self.width / max(self.height, 1)))
        self.distance = radius * margin / np.sin(half)
        return True

    def look_like(self, rotations) -> None:
        """Look the way a set of image cameras look (their mean orientation), image up as view up."""
        Rs = [np.asarray(r, float) for r in rotations]
        if not Rs:
            return
        # image camera: x right, y down, z forward; view: x right, y up, z backwards
        flip = np.diag([1.0, -1.0, -1.0])
        self.rotation = _orthonormal(sum(flip @ R for R in Rs))


def _finite_rows(X) -> np.ndarray:
    X = np.asarray(X, float).reshape(-1, 3)
    return X[np.all(np.isfinite(X), axis=1)]


# ---------------------------------------------------------------------------- scene
@dataclass
class Scene:
    """What to draw, as flat arrays (any may be empty).

    Attributes
    ----------
    points : ndarray (N, 3)
        World positions of round dots.
    point_colors : ndarray (N, 4)
        RGBA in 0..1.
    point_sizes : ndarray (N,)
        Diameters in pixels.  Dots later in the arrays are drawn over earlier
        ones at the same depth (a highlight disc goes before its point).
    lines : ndarray (M, 2, 3)
        World end points of line segments.
    line_colors : ndarray (M, 4)
        RGBA in 0..1.
    background : tuple
        RGB in 0..1.
    """

    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    point_colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    point_sizes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    line_colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    background: tuple = (0.14, 0.14, 0.15)

    def radius_about(self, centre: np.ndarray) -> float:
        """How far the scene reaches from ``centre`` (for the clip planes)."""
        pts = [_finite_rows(self.points), _finite_rows(self.lines.reshape(-1, 3))]
        X = np.concatenate(pts) if any(len(p) for p in pts) else np.zeros((0, 3))
        if not len(X):
            return 100.0
        return float(np.linalg.norm(X - centre, axis=1).max())


_VERTEX_SHADER = """
#version 330
uniform mat4 mvp;
in vec3 in_pos;
in vec4 in_color;
{size_in}
out vec4 v_color;
void main() {{
    gl_Position = mvp * vec4(in_pos, 1.0);
    {size_out}
    v_color = in_color;
}}
"""
_POINT_VS = _VERTEX_SHADER.format(size_in="in float in_size;", size_out="gl_PointSize = in_size;")
_LINE_VS = _VERTEX_SHADER.format(size_in="", size_out="")
_POINT_FS = """
#version 330
in vec4 v_color;
out vec4 f_color;
void main() {
    vec2 c = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(c, c);
    if (r2 > 1.0) discard;
    // a darker rim keeps neighbouring dots apart
    f_color = vec4(v_color.rgb * (r2 > 0.72 ? 0.55 : 1.0), v_color.a);
}
"""
_LINE_FS = """
#version 330
in vec4 v_color;
out vec4 f_color;
void main() { f_color = v_color; }
"""


class Renderer:
    """An offscreen OpenGL context and framebuffer that draws a :class:`Scene`.

    Parameters
    ----------
    width, height : int
        Framebuffer size in pixels.
    backend : str
        glcontext backend: ``"egl"`` works without a display server.

    Raises
    ------
    RenderUnavailable
        When no context can be created (the message says why).
    """

    def __init__(self, width: int = 640, height: int = 480, backend: str = "egl"):
        try:
            import moderngl
        except ImportError as e:            # pragma: no cover - moderngl is a dependency
            raise RenderUnavailable(f"moderngl is not installed ({e})") from e
        self._mgl = moderngl
        try:
            self.ctx = moderngl.create_standalone_context(backend=backend)
        except Exception as e:  # noqa: BLE001 - glcontext raises plain Exceptions with the loader's message
            raise RenderUnavailable(f"no OpenGL context on {backend.upper()}: {e}") from e
        self.gl_renderer = self.ctx.info.get("GL_RENDERER", "?")
        self.ctx.enable(moderngl.PROGRAM_POINT_SIZE | moderngl.DEPTH_TEST | moderngl.BLEND)
        self.ctx.depth_func = "<="
        self.point_prog = self.ctx.program(vertex_shader=_POINT_VS, fragment_shader=_POINT_FS)
        self.line_prog = self.ctx.program(vertex_shader=_LINE_VS, fragment_shader=_LINE_FS)
        self._buffers: dict[str, object] = {}
        self._vaos: dict[str, object] = {}
        self.fbo = None
        self.size = (0, 0)
        self.resize(width, height)

    def resize(self, width: int, height: int) -> None:
        """Reallocate the framebuffer (a no-op at the same size)."""
        size = (max(int(width), 1), max(int(height), 1))
        if size == self.size:
            return
        if self.fbo is not None:
            self.fbo.release()
        self.size = size
        self.fbo = self.ctx.simple_framebuffer(size, components=4)

    def _upload(self, name: str, prog, data: np.ndarray, layout: str, attrs: tuple):
        """A vertex array over ``data`` reusing the buffer of the last frame when it is big enough."""
        raw = np.ascontiguousarray(data, dtype="f4").tobytes()
        buf = self._buffers.get(name)
        if buf is None or buf.size < len(raw):
            if buf is not None:
                self._vaos.pop(name).release()
                buf.release()
            buf = self._buffers[name] = self.ctx.buffer(reserve=max(len(raw), 4096), dynamic=True)
            self._vaos[name] = self.ctx.vertex_array(prog, [(buf, layout, *attrs)])
        buf.write(raw)
        return self._vaos[name]

    def render(self, scene: Scene, camera: OrbitCamera) -> np.ndarray:
        """Draw ``scene`` seen by ``camera`` (at the framebuffer's size).

        Returns
        -------
        ndarray (height, width, 4) uint8
            RGBA, row 0 at the top.
        """
        mgl = self._mgl
        w, h = self.size
        camera.width, camera.height = w, h
        near, far = camera.clip_planes(scene.radius_about(camera.target))
        mvp = (camera.projection_matrix(near, far) @ camera.view_matrix()).astype("f4")
        # moderngl wants column-major matrices
        mvp_bytes = mvp.T.tobytes()
        self.fbo.use()
        self.ctx.viewport = (0, 0, w, h)
        self.ctx.clear(*scene.background, 1.0, depth=1.0)
        self.ctx.blend_func = mgl.SRC_ALPHA, mgl.ONE_MINUS_SRC_ALPHA
        n_lines = len(scene.lines)
        if n_lines:
            v = np.empty((n_lines * 2, 7), "f4")
            v[:, :3] = scene.lines.reshape(-1, 3)
            v[:, 3:] = np.repeat(np.asarray(scene.line_colors, "f4").reshape(-1, 4), 2, axis=0)
            ok = np.all(np.isfinite(v[:, :3]), axis=1).reshape(-1, 2).all(axis=1)
            v = v.reshape(-1, 2, 7)[ok].reshape(-1, 7)
            if len(v):
                self.line_prog["mvp"].write(mvp_bytes)
                self._upload("lines", self.line_prog, v, "3f 4f", ("in_pos", "in_color")).render(
                    mgl.LINES, vertices=len(v))
        n_pts = len(scene.points)
        if n_pts:
            v = np.empty((n_pts, 8), "f4")
            v[:, :3] = scene.points
            v[:, 3:7] = scene.point_colors
            v[:, 7] = scene.point_sizes
            v = v[np.all(np.isfinite(v[:, :3]), axis=1)]
            if len(v):
                self.point_prog["mvp"].write(mvp_bytes)
                self._upload("points", self.point_prog, v, "3f 4f 1f", ("in_pos", "in_color", "in_size")).render(
                    mgl.POINTS, vertices=len(v))
        data = self.fbo.read(components=4, alignment=1)
        return np.frombuffer(data, np.uint8).reshape(h, w, 4)

    def release(self) -> None:
        """Free the context (the renderer cannot draw afterwards)."""
        for vao in self._vaos.values():
            vao.release()
        for buf in self._buffers.values():
            buf.release()
        self._vaos.clear()
        self._buffers.clear()
        if self.fbo is not None:
            self.fbo.release()
            self.fbo = None
        self.ctx.release()


_shared: dict[str, object] = {}


def shared_renderer() -> Renderer:
    """One renderer per process: every 3D view draws with it in turn (contexts are costly under llvmpipe).

    Raises
    ------
    RenderUnavailable
        When no context can be created; the failure is remembered, so later
        views do not retry a broken driver.
    """
    r = _shared.get("renderer")
    if r is None:
        err = _shared.get("error")
        if err is not None:
            raise RenderUnavailable(str(err))
        try:
            r = _shared["renderer"] = Renderer(64, 64)
        except RenderUnavailable as e:
            _shared["error"] = e
            raise
    return r  # type: ignore[return-value]
