"""Step 10 of :class:`.engine.FrameTracker`: the rows it adds for markers that no point follows.

:mod:`.spawn` finds the matches; here a confirmed one becomes a row of every per-point array the tracker
carries from frame to frame, and of the frame's result.  Kept apart from the engine's per-frame steps: it
is the one place the tracked set grows.
"""
from __future__ import annotations

import numpy as np

from ..points import SRC_DETECTION, SRC_NONE, ST_RECONSTRUCTED
from . import elastic, spawn
from .finite import finite_rows
from .geometry import reprojection, round_views


class NewPoints:
    """The :class:`.engine.FrameTracker` methods of step 10 (they read and grow its per-point state)."""

    def _add_new_markers(self, frame, fd, rig, res, known):
        """Step 10: a point for each :func:`.spawn.candidates` match that the last frame found too, where its
        nearest measured points carried it (within :data:`.spawn.AGREE_MM`); the rest wait a frame."""
        measured = res.status == ST_RECONSTRUCTED
        free = fd.free.copy()
        free[fd.attached(res.det)[2]] = False
        ids = [np.flatnonzero(free[fd.offsets[s]:fd.offsets[s + 1]]) for s in range(self.S)]
        xy = [fd.xy[s][ids[s]] for s in range(self.S)]
        cut = fd.offsets
        blobs = [np.column_stack([fd.size_all[cut[s]:cut[s + 1], 0], fd.prob_all[cut[s]:cut[s + 1]]])[ids[s]]
                 for s in range(self.S)]
        # The markers' typical size (mm): the blob views of this frame's measured points.
        r, s, g = fd.attached(res.det, (res.src == SRC_DETECTION) & measured[:, None])
        marker_mm = float(np.median(fd.size_all[g, 0] * spawn.view_depth(rig, res.X[r])[np.arange(len(r)), s]
                                    / rig.K[s, 0, 0])) if len(r) else None
        spacing = self.pred_sd / self._prediction_sd(1.0)
        choice, Xn = spawn.candidates(rig, xy, res.X[measured], known, spacing, self.brim, blobs=blobs,
                                      marker_mm=marker_mm)
        if len(Xn) and self.images is not None:
            raw = [fd.raw[s][ids[s]] for s in range(self.S)]
            ref = [g[s == k] for k in range(self.S)]             # the measured points' blob views, per sensor
            keep = spawn.stands_out([lambda k=k: self._image(k, frame) for k in range(self.S)], choice, raw,
                                    [b[:, 0] for b in blobs], [fd.raw_all[gg] for gg in ref],
                                    [fd.size_all[gg, 0] for gg in ref])
            choice, Xn = choice[keep], Xn[keep]
        pending, self._pending = self._pending, None
        rows = np.flatnonzero(measured)
        if not len(Xn) or len(rows) < spawn.SURFACE_NEIGHBOURS:
            return
        nbr = rows[spawn.nearest(res.X[rows], Xn, spawn.SURFACE_NEIGHBOURS)]
        confirmed = np.zeros(len(Xn), bool)
        if pending is not None:
            confirmed = spawn.carried_to(*pending, res.X, Xn)
        self._pending = (Xn[~confirmed], nbr[~confirmed], res.X[nbr[~confirmed]])
        if np.any(confirmed):
            c = choice[confirmed]
            det = np.full(c.shape, -1)
            for s in range(self.S):
                use = c[:, s] >= 0
                det[use, s] = ids[s][c[use, s]]
            self.add_points(frame, fd, rig, res, Xn[confirmed], det, known)

    def add_points(self, frame, fd, rig, res, Xn, det, known):
        """Append points at ``Xn`` (n, 3), measured on this frame's detections ``det`` (n, S), to the tracked set
        and to this frame's result ``res``; ``known`` (N, 3): where the points there already are."""
        n, S, N = len(Xn), self.S, self.N
        src = np.where(det >= 0, SRC_DETECTION, SRC_NONE).astype(np.uint8)
        uv_raw = np.full((n, S, 2), np.nan)
        uv_c = np.full((n, S, 2), np.nan)
        size = np.full((n, S, 2), np.nan)
        r, s, g = fd.attached(det)
        uv_raw[r, s], uv_c[r, s], size[r, s] = fd.raw_all[g], fd.xy_all[g], fd.size_all[g]
        valid = det >= 0
        err = reprojection(rig, Xn, uv_c, valid)
        residual = np.sqrt(np.where(valid, err, 0.0) ** 2 @ np.ones(S) / valid.sum(1))
        # Their neighbours among every point where it is now; the points already tracked keep theirs.
        everyone = np.concatenate([np.where(finite_rows(known)[:, None], known, 1e6), Xn])
        nb = elastic.neighbours(everyone, mutual=elastic.MUTUAL)[N:]
        off = np.full(nb.shape + (3,), np.nan)
        have = (nb >= 0) & np.isin(nb, np.flatnonzero(finite_rows(res.X))) | (nb >= N)
        X_all = np.concatenate([res.X, Xn])
        off[have] = Xn[np.nonzero(have)[0]] - X_all[nb[have]]

        def grow(a, rows):
            return np.concatenate([a, rows])

        self.X, self.X_last = grow(self.X, Xn), grow(self.X_last, Xn)
        self.V = grow(self.V, np.full((n, 3), np.nan))
        self.uv_prev, self.size = grow(self.uv_prev, uv_raw), grow(self.size, size)
        self.nb, self.off = grow(self.nb, nb), grow(self.off, off)
        self.motion = grow(self.motion, np.zeros(nb.shape + (2,)))
        self.w = elastic.weights(self.motion)
        self.unseen = grow(self.unseen, np.zeros(n, self.unseen.dtype))
        self.held = grow(self.held, np.zeros(n, np.int64))
        self.patch_run = grow(self.patch_run, np.zeros(n, self.patch_run.dtype))
        self.tentative = grow(self.tentative, np.zeros(n, bool))
        self.tentative_views = grow(self.tentative_views, np.zeros((n, S), bool))
        self.single_return = grow(self.single_return, np.zeros(n, bool))
        self._blob_w, self._el = grow(self._blob_w, np.ones((n, S))), grow(self._el, round_views((n, S)))
        self.pred_sd = grow(self.pred_sd, self._prediction_sd(elastic.spacing(everyone)[N:]))
        self.post_var = grow(self.post_var, np.full(n, np.inf))
        self._post_new = grow(self._post_new, np.full(n, np.inf))
        self.blob_frame = grow(self.blob_frame, np.where(valid, frame, -1))
        self.blob_uv = grow(self.blob_uv, uv_raw)
        self.seen = grow(self.seen, valid)
        self.N = N + n
        res.X, res.status = X_all, grow(res.status, np.full(n, ST_RECONSTRUCTED, res.status.dtype))
        res.residual, res.src, res.det = grow(res.residual, residual), grow(res.src, src), grow(res.det, det)
        res.uv = grow(res.uv, uv_raw)
        res.score = grow(res.score, np.where(valid, 1.0, np.nan))
        res.new = n
