#!/usr/bin/env python
"""Train the blob-centre classifiers shipped in ``resources/blob_model_{black,white}.npz``.

Examples are generated (``carapost.core.blobs.synth``): markers over varied
skin tone, shading, blur, noise and partial occlusion by the brim, among the
confusers of a face (nostrils, eye corners, brows, hair, brim edges, specular
highlights).  The candidate finder of the detector runs on each image; every
candidate is labelled positive when it lies near a visible marker's centre,
negative when it is away from every marker, and left out when ambiguous.
Stage 1 (candidate features) is trained first; then every candidate it lets
through is fitted and stage 2 (fit features plus the stage-1 logit) is trained
on the fits, positive when the fitted centre is within 1 px of the truth.  With
``--edge-scenes N`` a third network, the edge stage, is trained the same way on
the ellipses found from a candidate's own edge alone (more scenes of them), from
stage 2's features and logit and the edge's own features (how it scatters, how
many rays found it, how strong it is); ``--edge-fpr`` sets how many false ones
it may add against the rule it stands beside.  Each
stage is a one-hidden-layer tanh network fitted with full-batch Adam on the
class-balanced logistic loss.  Everything is seeded: the same command gives
the same weights.

With ``--centre-scenes N`` the **centre stage** (step 9, ``carapost.core.blobs.centre_net``) is trained
too: every detection (steps 1-8, the classifier just trained or, with ``--centre-only``, the one in
``--out``) within 1.5 px of a marker of the generated images, of N sample-take scenes more (seeds 3000
and up; a tenth as many jaw-open ones) and of N generated images of large dots is an example; its inputs
are the grey levels on the grid about it and its target is how far its centre is off, along and across
its ellipse.  The network (tanh layers,
``--centre-hidden``: two of 96 and 48 units by default, or one; a linear output) is fitted with minibatch
Adam on the squared error, each example seen in its four mirror images (the grid flipped along either axis,
the target's sign with it).

With ``--orphan-scenes N`` the **orphan gate** is trained too (``--orphan-only``: it alone, over the stages in
``--out``): the threshold components about the candidates no believed fit explains
(``carapost.core.blobs.detector._with_orphans``) of N sample-take scenes more (seeds 4000 and up; a third as many
jaw-open ones, seeds 4500 and up), each labelled by whether step 5's search from it ends as a fit the detector
keeps at the default threshold; its bias lets every such training component through.

Usage::

    python tools/train_blob_model.py [--images 160] [--scenes 3] [--jaw-scenes 0] [--grazing 0] [--edge-scenes 0]
                                     [--edge-fpr 0.5] [--edge-only] [--orphan-scenes 0] [--orphan-only]
                                     [--colour both] [--seed 5] [--out resources]

The shipped edge stages (session 28) were made, over the shipped stages 1 and 2, with::

    python tools/train_blob_model.py --images 200 --edge-scenes 30 --edge-fpr 0.5 --edge-only --seed 5

the shipped orphan gates (session 44), over the shipped stages 1, 2 and edge, with::

    python tools/train_blob_model.py --orphan-scenes 40 --orphan-only --seed 5

and the shipped centre stages, over the shipped stages 1, 2 and edge, white's (two layers, session 40) and
black's (one layer of 64 units, session 39), with::

    python tools/train_blob_model.py --images 200 --centre-scenes 200 --centre-only --seed 5 --colour white
    python tools/train_blob_model.py --images 200 --centre-scenes 200 --centre-only --seed 5 --colour black \
        --centre-hidden 64
"""
from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from carapost.core.blobs.centre_net import GRID, CentreNet, centre_inputs  # noqa: E402
from carapost.core.blobs import detector as blob_detector  # noqa: E402
from carapost.core.blobs.detector import (RESCUE_LOGIT, _refine_edge_ellipses, as_grey_u8, detect,  # noqa: E402
                                         find_candidates, fit_stage, orphan_components, orphan_features,
                                         orphan_fits)
from carapost.core.blobs.features import noise_sigma  # noqa: E402
from carapost.core.blobs.model import MLP, ORPHAN_FEATURE_NAMES, BlobModel  # noqa: E402
from carapost.core.blobs.synth import render, render_grazing, sample_frames  # noqa: E402


def images(white: bool, n_images: int, seed: int):
    """Generated training images of one colour.

    Every fourth has large markers; every third of the others has oblique ones
    (minor/major down to 0.15, as dots near a face's silhouette or on a brim seen
    edge-on are), so the default threshold finds those too.
    """
    rng = np.random.default_rng([seed, int(white)])
    out = []
    for i in range(n_images):
        big = i % 4 == 3
        oblique = not big and i % 3 == 1
        out.append(render(rng, 360, 480, markers=30 if not big else 12, white=white,
                          radius=(1.8, 7.0) if not big else (6.0, 22.0),
                          aspect=(0.15, 0.6) if oblique else (0.55, 1.0), confusers=int(rng.integers(3, 14))))
    return out


def sample_takes(white: bool, scenes: int, seed: int):
    """Frames of ``carapost sample`` takes: 3 frames x 4 cameras per scene, varied noise and blur.

    Its faces, brim and lighting are what the accuracy benchmark measures on; the
    takes' seeds start at 1000 so the benchmark's (0-5) are never trained on.  Dots
    the paint does not show (black on a dense black eyebrow: ``faint``) are with the
    hidden ones, so candidates on them are neither positives (they look like brow
    hair, and taught stage 1 that hair is a dot) nor negatives.
    """
    rng = np.random.default_rng([seed, int(white), 7])
    return _scenes(white, 1000 + 10 * seed, scenes, rng, (60, 160), frames=3, step=37)


def _scenes(white: bool, first: int, count: int, rng, markers: tuple, **kw):
    """``count`` sample-take scenes of seeds ``first`` on (``sample_frames(**kw)``), each with a number of face
    markers in ``markers`` and a noise of 1-4 and a blur of 0.5-1.2, drawn from ``rng`` in that order."""
    out = []
    for k in range(count):
        out += sample_frames(white, seed=first + k, markers=int(rng.integers(*markers)),
                             noise=float(rng.uniform(1.0, 4.0)), blur=float(rng.uniform(0.5, 1.2)), **kw)
    return out


def jaw_takes(white: bool, scenes: int, seed: int):
    """Frames of ``carapost sample`` takes with the jaw open widest: 2 frames x 4 cameras per scene.

    The lower-lip and chin dots then face the cameras at 60-80 degrees (thin ellipses) on the
    dark band of the jaw's shadow beside the teeth, which the takes' other frames rarely show:
    without them the classifier dropped most such views.  Seeds 2000 + 10 seed + k (never the
    benchmark's); 35-160 face markers.
    """
    rng = np.random.default_rng([seed, int(white), 11])
    return _scenes(white, 2000 + 10 * seed, scenes, rng, (35, 160), jaw_open=2)


def grazing_images(white: bool, n_images: int, seed: int):
    """Generated images of thin dots seen at grazing angles beside a face's outline, nostrils and open mouth.

    On the sample takes most missed markers are such views (minor semi-axis 0.5-1.4 px): cheek,
    temple, jaw and chin dots near the outline, nostril dots at the nostril's rim, lower-lip dots
    on the jaw's shadow beside the teeth (``synth.render_grazing``).
    """
    rng = np.random.default_rng([seed, int(white), 13])
    return [render_grazing(rng, 360, 480, white=white, structures=int(rng.integers(2, 5)),
                           confusers=int(rng.integers(2, 8))) for _ in range(n_images)]


def _labels(pts: np.ndarray, s, tol: np.ndarray, strict: np.ndarray | None = None):
    """(positive, usable) for points against one image's truth.

    A point on a marker's body or edge but off its centre is left out, except
    where ``strict``: there it is a negative.
    """
    pos = np.zeros(len(pts), bool)
    near = np.zeros(len(pts), bool)
    if len(s.centres):
        d = np.linalg.norm(pts[:, None] - s.centres[None], axis=2)
        j = d.argmin(1)
        dm = d[np.arange(len(pts)), j]
        pos = dm <= tol
        # On a marker's body or edge but off its centre: neither (the fit recentres them).
        near = ~pos & (dm < s.axes[j, 0] + 2.5)
        if strict is not None:
            near &= ~strict
    if len(s.hidden):
        near |= np.linalg.norm(pts[:, None] - s.hidden[None], axis=2).min(1) < 10.0
    return pos, pos | ~near


def stage1_examples(data, white: bool):
    """Candidate features and labels: positive near a visible marker's centre."""
    F, Y = [], []
    for s in data:
        c, _ = find_candidates(as_grey_u8(s.image), white, 2.0, 60.0)
        if len(c.x) == 0:
            continue
        # The narrower DoG's maxima off a marker's centre are negatives: they are the ring of maxima it
        # makes inside every larger dot, which the ordinary DoG's candidate measures already.  Left out, as
        # the ordinary ones are, stage 1 passed them and they were fitted: 37 of the narrower DoG's
        # candidates a frame (15 on markers off centre) on the black frames of seeds 0-2, 18 (5) with this.
        pos, use = _labels(np.stack([c.x, c.y], 1), s, np.maximum(1.5, 0.75 * 2.0 ** c.level), c.thin)
        F.append(c.feats[use])
        Y.append(pos[use])
    return np.concatenate(F), np.concatenate(Y).astype(np.float32)


def stage2_examples(data, white: bool, model: BlobModel):
    """Fitted-blob features and labels: positive when the fitted centre is within 1 px of the truth."""
    F, Y = [], []
    for s in data:
        c, bright = find_candidates(as_grey_u8(s.image), white, 2.0, 60.0)
        if len(c.x) == 0:
            continue
        # Without the orphan search (session 44): the shipped stages were trained before it, and its fits are the
        # edge stage's to score.
        fit = fit_stage(c, bright, model, orphans=False)
        pts = np.stack([fit.x, fit.y], 1)
        pos, use = _labels(pts, s, np.full(len(pts), 1.0))
        use &= fit.ok
        F.append(fit.feats[use])
        Y.append(pos[use])
    return np.concatenate(F), np.concatenate(Y).astype(np.float32)


def edge_examples(data, white: bool, model: BlobModel, orphans: bool = False):
    """Stage-2 features, edge features and labels of the ellipses found from a candidate's own edge
    (``from_edge``).

    Labelled as stage 2's examples; returns the stage-2 features, the edge features
    (:data:`~carapost.core.blobs.model.EDGE_FEATURE_NAMES`), the labels and which examples are usable
    (the others lie on a marker off its centre or near a hidden one).  With ``orphans`` the ellipses of the
    orphan search are examples too, from every threshold component (no gate: the gate learns from this stage).
    """
    F, Q, Y, U = [], [], [], []
    ungated = BlobModel(model.stage1, model.stage2, model.edge, model.centre)
    for s in data:
        c, bright = find_candidates(as_grey_u8(s.image), white, 2.0, 60.0)
        if len(c.x) == 0:
            continue
        fit = fit_stage(c, bright, ungated, orphans=orphans)
        if fit.from_edge is None:
            continue
        sel = np.flatnonzero(fit.from_edge & fit.ok)
        # Labelled where detect() puts them: step 5 along their own normals may move them up to 1 px.
        x, y = _refine_edge_ellipses(bright, fit.x[sel], fit.y[sel], fit.major[sel], fit.minor[sel], fit.angle[sel],
                                     not white)
        pos, use = _labels(np.stack([x, y], 1), s, np.full(len(sel), 1.0))
        F.append(fit.feats[sel])
        Q.append(fit.edge_feats[sel])
        Y.append(pos)
        U.append(use)
    if not F:
        z = np.zeros((0, 0), np.float32)
        return z, z, np.zeros(0, np.float32), np.zeros(0, bool)
    return np.concatenate(F), np.concatenate(Q), np.concatenate(Y).astype(np.float32), np.concatenate(U)


#: The detector's default threshold (the guide's Black/White Threshold), as a logit.
AT = np.log(0.4 / 0.6)


def centre_takes(white: bool, scenes: int, seed: int):
    """Frames of ``carapost sample`` takes for the centre stage: ``scenes`` scenes of 3 frames x 4 cameras and a
    tenth as many jaw-open ones (2 frames x 4 cameras), seeds from 3000 (never the benchmark's or the other
    stages'); 35-160 face markers, varied noise and blur."""
    rng = np.random.default_rng([seed, int(white), 17])
    first = 3000 + 10 * seed
    return (_scenes(white, first, scenes, rng, (35, 160), frames=3, step=37)
            + _scenes(white, first + scenes, scenes // 10, rng, (35, 160), jaw_open=2))


def large_images(white: bool, n_images: int, seed: int):
    """Generated images of large dots (semi-axes 5-24 px) for the centre stage: the sample takes' face dots are
    3-7 px, and a network that had seen few larger ones moved their centres the wrong way."""
    rng = np.random.default_rng([seed, int(white), 19])
    return [render(rng, 360, 480, markers=12, white=white, radius=(5.0, 24.0), confusers=int(rng.integers(3, 14)))
            for _ in range(n_images)]


@contextmanager
def _without_orphans():
    """Detection without the orphan search (:data:`carapost.core.blobs.detector.ORPHANS`) within the block."""
    before = blob_detector.ORPHANS
    blob_detector.ORPHANS = False
    try:
        yield
    finally:
        blob_detector.ORPHANS = before


def centre_examples(data, white: bool, model: BlobModel, tol: float = 1.5):
    """The centre stage's examples: inputs (:func:`~carapost.core.blobs.centre_net.centre_inputs`) of every
    detection (steps 1-8) within ``tol`` px of a visible marker, and its centre's error (detected less true, px)
    along and across its ellipse's major axis."""
    from scipy.spatial import cKDTree

    X, Y = [], []
    for s in data:
        img = as_grey_u8(s.image)
        with _without_orphans():      # as the shipped centre stages were trained (sessions 39-40)
            rec = detect(img, white=white, model=model, learned_centres=False)
        if len(rec) == 0 or len(s.centres) == 0:
            continue
        d, j = cKDTree(np.column_stack([rec["x"], rec["y"]]).astype(np.float64)).query(s.centres)
        # One detection per marker, the nearest; a detection nearest two markers serves the nearer.
        best = {}
        for k in np.flatnonzero(d <= tol):
            if j[k] not in best or d[k] < d[best[j[k]]]:
                best[j[k]] = k
        if not best:
            continue
        det = np.array(list(best.keys()))
        mk = np.array(list(best.values()))
        r = rec[det]
        bright = img if white else 255 - img
        inputs, _ = centre_inputs(bright, r["x"], r["y"], r["major"], r["minor"], r["angle"], noise_sigma(img))
        e = np.column_stack([r["x"], r["y"]]).astype(np.float64) - s.centres[mk]
        th = np.deg2rad(r["angle"].astype(np.float64))
        co, si = np.cos(th), np.sin(th)
        X.append(inputs)
        Y.append(np.column_stack([e[:, 0] * co + e[:, 1] * si, -e[:, 0] * si + e[:, 1] * co]))
    return np.concatenate(X), np.concatenate(Y).astype(np.float32)


def _mirrored(X: np.ndarray, Y: np.ndarray):
    """``X``, ``Y`` and their three mirror images: the grid flipped along the major axis, across it, and both
    (the error's component along the flipped axis changes sign)."""
    grid = X[:, :GRID * GRID].reshape(-1, GRID, GRID)       # rows: across (v), columns: along (u)
    xs, ys = [], []
    for fu in (1, -1):
        for fv in (1, -1):
            xs.append(np.hstack([grid[:, ::fv, ::fu].reshape(len(X), -1), X[:, GRID * GRID:]]))
            ys.append(Y * np.array([fu, fv], np.float32))
    return np.concatenate(xs), np.concatenate(ys)


#: The centre stage's hidden layers (units each) unless ``--centre-hidden`` says otherwise: white's since session 40.
CENTRE_HIDDEN = (96, 48)


def train_centre(X: np.ndarray, Y: np.ndarray, seed: int, hidden: tuple = CENTRE_HIDDEN, epochs: int = 40,
                 batch: int = 512, lr: float = 2e-3, decay: float = 1e-4) -> CentreNet:
    """The centre stage: minibatch Adam on the squared error of a network of one or two tanh layers (``hidden``
    units each; learning rate on a cosine from ``lr`` to 0 over ``epochs``, weight decay on the hidden layers), on
    the examples and their mirror images."""
    X, Y = _mirrored(X, Y)
    rng = np.random.default_rng(seed)
    mean = X.mean(0)
    std = X.std(0) + 1e-6
    Z = ((X - mean) / std).astype(np.float32)
    n, d = Z.shape
    sizes = (d, *hidden)
    params = []
    for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
        params += [(rng.standard_normal((fan_in, fan_out)) / np.sqrt(fan_in)).astype(np.float32),
                   np.zeros(fan_out, np.float32)]
    params += [(rng.standard_normal((sizes[-1], 2)) * 0.01).astype(np.float32), np.zeros(2, np.float32)]
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    t = 0
    for ep in range(epochs):
        order = rng.permutation(n)
        step = lr * 0.5 * (1.0 + np.cos(np.pi * ep / epochs))
        for s in range(0, n, batch):
            idx = order[s:s + batch]
            acts = [Z[idx]]
            for k in range(0, len(params) - 2, 2):
                acts.append(np.tanh(acts[-1] @ params[k] + params[k + 1]))
            err = acts[-1] @ params[-2] + params[-1] - Y[idx]
            grads = [acts[-1].T @ err / len(idx), err.mean(0)]
            g = err @ params[-2].T
            for k in range(len(params) - 4, -1, -2):
                g = g * (1.0 - acts[k // 2 + 1] ** 2)
                grads = [acts[k // 2].T @ g / len(idx) + decay * params[k], g.mean(0)] + grads
                g = g @ params[k].T
            t += 1
            for k, g in enumerate(grads):
                m[k] = 0.9 * m[k] + 0.1 * g
                v[k] = 0.999 * v[k] + 0.001 * g * g
                params[k] = (params[k] - step * (m[k] / (1 - 0.9 ** t)) / (np.sqrt(v[k] / (1 - 0.999 ** t)) + 1e-8)
                             ).astype(np.float32)
    hidden_pair = params[2:4] if len(hidden) == 2 else [None, None]
    return CentreNet(mean.astype(np.float32), std.astype(np.float32), params[0], params[1], params[-2], params[-1],
                     *hidden_pair)


def _centre_stage(model: BlobModel, white: bool, a) -> CentreNet:
    """Train the centre stage for ``model`` (``--centre-scenes``) and report it."""
    data = images(white, a.images, a.seed) + centre_takes(white, a.centre_scenes, a.seed)
    data += large_images(white, a.centre_scenes, a.seed)
    X, Y = centre_examples(data, white, model)
    net = train_centre(X, Y, a.seed + 3, hidden=a.centre_hidden)
    after = Y - net.error(X)
    print(f"centre stage: {len(Y)} detections, centre RMS on them {np.sqrt((Y ** 2).sum(1).mean()):.4f} -> "
          f"{np.sqrt((after ** 2).sum(1).mean()):.4f} px (before the texture gate)")
    return net


def rule_keeps(model: BlobModel, F: np.ndarray) -> np.ndarray:
    """Which edge ellipses of stage-2 features ``F`` the rule keeps at the default threshold: stage 2's logit
    less ``RESCUE_LOGIT`` (what detection scores them by without an edge stage)."""
    return model.stage2.logit(F) - RESCUE_LOGIT >= AT


def train_edge(model: BlobModel, F: np.ndarray, Q: np.ndarray, Y: np.ndarray, seed: int, fpr: float = 0.5) -> MLP:
    """The edge stage: a network over stage 2's features and logit and the edge's features ``Q``, trained
    on edge ellipses alone.

    Its output bias is set so that the default threshold (0.4) passes ``fpr`` times the share of the
    negatives that the rule before it passes (stage 2's logit less ``RESCUE_LOGIT``).  Detection takes
    the larger of the two scores (:meth:`~carapost.core.blobs.model.BlobModel.score`): the edge stage adds
    what the rule missed, it does not drop what the rule kept.
    """
    X = model.edge_features(F, Q)
    mlp = train(X, Y, seed, hidden=8)
    neg = Y < 0.5
    before = rule_keeps(model, F[neg]).mean()
    thr = np.quantile(mlp.logit(X[neg]), 1.0 - fpr * before)
    mlp.b2 = float(mlp.b2 - thr + AT)
    return mlp


def train(F: np.ndarray, Y: np.ndarray, seed: int, hidden: int = 16, iters: int = 3000) -> MLP:
    """Full-batch Adam on the class-balanced logistic loss of a one-hidden-layer network."""
    rng = np.random.default_rng(seed)
    mean = F.mean(0)
    std = F.std(0) + 1e-6
    Z = ((F - mean) / std).astype(np.float64)
    n, d = Z.shape
    wpos = 0.5 / max(Y.mean(), 1e-6)
    wneg = 0.5 / max(1 - Y.mean(), 1e-6)
    sw = np.where(Y > 0.5, wpos, wneg) / n
    params = [rng.normal(0, 1 / np.sqrt(d), (d, hidden)), np.zeros(hidden), rng.normal(0, 1 / np.sqrt(hidden), hidden),
              np.zeros(1)]
    m = [np.zeros_like(p) for p in params]
    v = [np.zeros_like(p) for p in params]
    lr, b1, b2, decay = 0.02, 0.9, 0.999, 1e-4
    for t in range(1, iters + 1):
        W1, c1, W2, c2 = params
        H = np.tanh(Z @ W1 + c1)
        s = H @ W2 + c2[0]
        p = 1 / (1 + np.exp(-s))
        g = (p - Y) * sw
        gW2 = H.T @ g + decay * W2
        gc2 = np.array([g.sum()])
        gH = np.outer(g, W2) * (1 - H * H)
        gW1 = Z.T @ gH + decay * W1
        gc1 = gH.sum(0)
        for k, gk in enumerate((gW1, gc1, gW2, gc2)):
            m[k] = b1 * m[k] + (1 - b1) * gk
            v[k] = b2 * v[k] + (1 - b2) * gk * gk
            params[k] = params[k] - lr * (m[k] / (1 - b1 ** t)) / (np.sqrt(v[k] / (1 - b2 ** t)) + 1e-8)
    W1, c1, W2, c2 = params
    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    return MLP(f32(mean), f32(std), f32(W1), f32(c1), f32(W2), float(c2[0]))


def calibrate(mlp: MLP, F: np.ndarray, Y: np.ndarray, recall: float = 0.99, at: float = 0.4) -> MLP:
    """Shift the output bias so the guide's default threshold keeps ``recall`` of the training blobs.

    The class-balanced loss puts the 50 % point between the classes; the guide's
    default (0.4) should instead sit where almost every real blob passes, since a
    missed marker costs an artist more than a false detection (they can delete those).
    """
    lg = mlp.logit(F[Y > 0.5])
    if len(lg) == 0:
        return mlp
    need = np.log(at / (1 - at)) - np.quantile(lg, 1 - recall)
    if need > 0:
        mlp.b2 = float(mlp.b2 + need)
    return mlp


def _edge_stage(model: BlobModel, white: bool, a) -> MLP:
    """Train the edge stage for ``model`` (``--edge-scenes``) and report it."""
    data = images(white, a.images, a.seed) + sample_takes(white, a.edge_scenes, a.seed)
    data += jaw_takes(white, a.edge_scenes, a.seed)
    F, Q, Y, U = edge_examples(data, white, model, a.edge_orphans)
    edge = train_edge(model, F[U], Q[U], Y[U], a.seed + 2, a.edge_fpr)
    pos, neg = (Y > 0.5) & U, (Y < 0.5) & U
    before = rule_keeps(model, F)
    after = before | (edge.predict(model.edge_features(F, Q)) >= 0.4)
    print(f"edge stage: {int(U.sum())} edge ellipses ({int(pos.sum())} blobs) at 0.4: recall {before[pos].mean():.4f} -> "
          f"{after[pos].mean():.4f}, false {before[neg].mean():.4f} -> {after[neg].mean():.4f}")
    return edge


def orphan_takes(white: bool, scenes: int, seed: int):
    """Frames of ``carapost sample`` takes for the orphan gate: seeds 4000 + 10 seed + k (never the benchmark's),
    3 frames x 4 cameras a scene, and a third as many jaw-open scenes (2 frames x 4 cameras)."""
    rng = np.random.default_rng([seed, int(white), 17])
    out = _scenes(white, 4000 + 10 * seed, scenes, rng, (60, 160), frames=3, step=37)
    return out + _scenes(white, 4500 + 10 * seed, max(1, scenes // 3), rng, (35, 160), jaw_open=2)


def _orphan_components(data, white: bool, model: BlobModel, gated: bool):
    """Per image of ``data``: the image, its candidates, "bright blob" image and stage-1 logits, and the candidates
    and threshold components the orphan search looks at (through ``model``'s gate when ``gated``)."""
    for s in data:
        c, bright = find_candidates(as_grey_u8(s.image), white, 4.0, 50.0)
        if len(c.x) == 0:
            continue
        logit1 = model.stage1.logit(c.feats)
        prob1 = 1.0 / (1.0 + np.exp(-np.clip(logit1, -30, 30)))
        fin, comp = orphan_components(fit_stage(c, bright, model, orphans=False), c, bright, model, prob1)
        if gated and model.orphan is not None and len(fin):
            look = model.orphan.logit(orphan_features(c, fin, comp, logit1)) >= 0.0
            fin, comp = fin[look], comp[look]
        if len(fin):
            yield s, c, bright, logit1, fin, comp


def orphan_examples(data, white: bool, model: BlobModel):
    """The orphan gate's inputs of every threshold component the detector finds about the candidates no believed
    fit explains, and whether step 5's search from it ends as a fit that the detector keeps at the default
    threshold (clean, thin, ``ok``, scored 0.4 or more: what the gate must let through)."""
    X, Y = [], []
    for _, c, bright, logit1, fin, comp in _orphan_components(data, white, model, gated=False):
        good, e, ok, F, Q = orphan_fits(c, bright, fin, comp, logit1)
        kept = np.zeros(len(fin), bool)
        # The edge stage's verdicts, with or without an orphan scorer: the scorer rescores what the gate lets through
        # (a gate trained on its verdicts let three to five times as many components through, session 44).
        kept[good] = ok & (model.score(F, np.ones(len(F), bool), RESCUE_LOGIT, Q) >= 0.4)
        X.append(orphan_features(c, fin, comp, logit1))
        Y.append(kept)
    if not X:
        return np.zeros((0, len(ORPHAN_FEATURE_NAMES)), np.float32), np.zeros(0, np.float32)
    return np.concatenate(X), np.concatenate(Y).astype(np.float32)


def orphan_fit_examples(data, white: bool, model: BlobModel):
    """The orphan scorer's examples: the edge stage's inputs of the fits the orphan search makes through ``model``'s
    gate (``ok`` ones), labelled as stage 2's examples, and how the rescue's ellipses would score them (the edge
    stage). Returns the inputs, the labels, which are usable, and those scores."""
    X, Y, U, S = [], [], [], []
    for s, c, bright, logit1, fin, comp in _orphan_components(data, white, model, gated=True):
        good, e, ok, F, Q = orphan_fits(c, bright, fin, comp, logit1)
        if not ok.any():
            continue
        e, F, Q = e[ok], F[ok], Q[ok]
        # Labelled where detect() puts them (step 5 along their own normals).
        x, y = _refine_edge_ellipses(bright, e[:, 0], e[:, 1], e[:, 2], e[:, 3], e[:, 4], not white)
        pos, use = _labels(np.stack([x, y], 1), s, np.full(len(x), 1.0))
        X.append(model.edge_features(F, Q))
        Y.append(pos)
        U.append(use)
        S.append(model.score(F, np.ones(len(F), bool), RESCUE_LOGIT, Q))
    if not X:
        return np.zeros((0, 0), np.float32), np.zeros(0, np.float32), np.zeros(0, bool), np.zeros(0)
    return np.concatenate(X), np.concatenate(Y).astype(np.float32), np.concatenate(U), np.concatenate(S)


def _orphan_scorer(model: BlobModel, white: bool, a) -> MLP:
    """Train the orphan scorer for ``model`` (``--orphan-scorer-scenes``) and report it.

    Trained on the gated fits of N scenes (seeds of ``orphan_takes(seed + 2)``); its threshold is set on the fits of
    N / 2 other scenes (``orphan_takes(seed + 4)``), held back from the training, so that it keeps as many of their
    fits off every dot as the edge stage does: it may only keep more of the dots.
    """
    X, Y, U, _ = orphan_fit_examples(orphan_takes(white, a.orphan_scorer_scenes, a.seed + 2), white, model)
    scorer = train(X[U], Y[U], a.seed + 6, hidden=8)
    Xc, Yc, Uc, Sc = orphan_fit_examples(orphan_takes(white, max(1, a.orphan_scorer_scenes // 2), a.seed + 4), white,
                                         model)
    neg, pos = (Yc < 0.5) & Uc, (Yc > 0.5) & Uc
    kept = int((Sc[neg] >= 0.4).sum())
    z = np.sort(scorer.logit(Xc[neg]))[::-1]
    # Between the kept-th and the next negative's logits, so that as many stay over the threshold.
    thr = 0.5 * (z[kept - 1] + z[kept]) if 0 < kept < len(z) else (z[0] + 1.0 if kept == 0 else z[-1] - 1.0)
    scorer.b2 = float(scorer.b2 - thr + AT)
    print(f"orphan scorer: {int(U.sum())} training fits, {int(Uc.sum())} held back; at 0.4 on those held back: on a dot "
          f"{(Sc[pos] >= 0.4).sum()} -> {(scorer.predict(Xc[pos]) >= 0.4).sum()} of {int(pos.sum())}, off every dot "
          f"{kept} -> {int((scorer.predict(Xc[neg]) >= 0.4).sum())}")
    return scorer


def _orphan_gate(model: BlobModel, white: bool, a) -> MLP:
    """Train the orphan gate for ``model`` (``--orphan-scenes``) and report it.

    Its output bias is set so that it lets through every training component whose search ended as a kept fit
    (the lowest such logit is 0): it only saves the searches, it should not change what is found.
    """
    X, Y = orphan_examples(orphan_takes(white, a.orphan_scenes, a.seed), white, model)
    gate = train(X, Y, a.seed + 3, hidden=8)
    gate.b2 = float(gate.b2 - gate.logit(X[Y > 0.5]).min()) if (Y > 0.5).any() else gate.b2
    print(f"orphan gate: {len(Y)} components ({int(Y.sum())} kept fits); it lets through "
          f"{(gate.logit(X) >= 0).mean():.3f} of them")
    return gate


def _layers(text: str) -> tuple:
    """``--centre-hidden``: one or two positive unit counts, comma-separated (step 9 runs one or two layers)."""
    try:
        units = tuple(int(n) for n in text.split(","))
    except ValueError:
        units = ()
    if len(units) not in (1, 2) or min(units) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: one or two positive unit counts, e.g. 96,48 or 64")
    return units


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", type=int, default=160, help="generated training images per colour")
    ap.add_argument("--scenes", type=int, default=3, help="sample-take scenes per colour (4 cameras x 3 frames each)")
    ap.add_argument("--jaw-scenes", type=int, default=0,
                    help="sample-take scenes per colour with the jaw open widest (4 cameras x 2 frames each)")
    ap.add_argument("--grazing", type=int, default=0,
                    help="generated images per colour of thin dots beside the face's outline, nostrils and mouth")
    ap.add_argument("--edge-scenes", type=int, default=0,
                    help="train the edge stage too, on the edge ellipses of the generated images and of this many "
                         "sample-take and jaw-open scenes more per colour (0: no edge stage)")
    ap.add_argument("--edge-fpr", type=float, default=0.5,
                    help="the edge stage's false detections at the default threshold, as a share of those of the "
                         "rule it stands beside (stage 2 less RESCUE_LOGIT)")
    ap.add_argument("--edge-orphans", action="store_true",
                    help="the edge stage's examples include the orphan search's ellipses (retrain the orphan gate "
                         "after it)")
    ap.add_argument("--edge-only", action="store_true",
                    help="keep the stages 1 and 2 in --out and (re)train only the edge stage")
    ap.add_argument("--orphan-scenes", type=int, default=0,
                    help="train the orphan gate too, on the threshold components of this many sample-take scenes "
                         "(and a third as many jaw-open ones) per colour (0: no gate; every component is searched)")
    ap.add_argument("--orphan-scorer-scenes", type=int, default=0,
                    help="train the orphan scorer too, on the orphan search's fits of this many sample-take scenes "
                         "(and half as many held back for its threshold) per colour (0: none; its fits are scored "
                         "by the edge stage)")
    ap.add_argument("--orphan-scorer-only", action="store_true",
                    help="keep the other stages in --out and (re)train only the orphan scorer")
    ap.add_argument("--orphan-only", action="store_true",
                    help="keep the other stages in --out and (re)train only the orphan gate")
    ap.add_argument("--centre-scenes", type=int, default=0,
                    help="train the centre stage too, on the detections of the generated images and of this many "
                         "sample-take scenes more per colour (0: no centre stage)")
    ap.add_argument("--centre-hidden", type=_layers, default=CENTRE_HIDDEN,
                    help="the centre stage's hidden layers, units each, comma-separated (one or two layers)")
    ap.add_argument("--centre-only", action="store_true",
                    help="keep the other stages in --out and (re)train only the centre stage")
    ap.add_argument("--colour", choices=("both", "black", "white"), default="both",
                    help="train one colour's weights only (the other's file is left as it is)")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "resources"))
    a = ap.parse_args(argv)
    for white in {"both": (False, True), "black": (False,), "white": (True,)}[a.colour]:
        t = time.time()
        name = "white" if white else "black"
        path = Path(a.out) / f"blob_model_{name}.npz"
        # --edge-only, --orphan-only, --centre-only: that stage alone, over the others in --out.
        alone = [(attr, title, train_stage) for flag, attr, title, train_stage in (
            (a.edge_only, "edge", "edge stage", _edge_stage), (a.orphan_only, "orphan", "orphan gate", _orphan_gate),
            (a.orphan_scorer_only, "orphan_score", "orphan scorer", _orphan_scorer),
            (a.centre_only, "centre", "centre stage", _centre_stage)) if flag]
        if alone:
            model = BlobModel.load(path)
            for attr, title, train_stage in alone:
                setattr(model, attr, train_stage(model, white, a))
                print(f"{name}: {title} only; {time.time() - t:.0f} s")
            model.save(path)
            print(f"{name} -> {path}")
            continue
        data = images(white, a.images, a.seed) + sample_takes(white, a.scenes, a.seed)
        data += jaw_takes(white, a.jaw_scenes, a.seed)
        grazing = grazing_images(white, a.grazing, a.seed)
        F1, Y1 = stage1_examples(data + grazing, white)
        model = BlobModel(train(F1, Y1, a.seed))
        F2, Y2 = stage2_examples(data, white, model)
        Fg, Yg = stage2_examples(grazing, white, model) if grazing else (F2[:0], Y2[:0])
        # The grazing views are taught, but the default threshold is set on the others: they are the hardest
        # positives, and calibrated with them the threshold follows their worst 1 %, not the ordinary dots'
        # (docs/blobs-history.md, "Grazing-angle training images": black false detections 55 -> 52, white 24 -> 21).
        model.stage2 = calibrate(train(np.concatenate([F2, Fg]), np.concatenate([Y2, Yg]), a.seed + 1, hidden=12),
                                 F2, Y2)
        F2, Y2 = np.concatenate([F2, Fg]), np.concatenate([Y2, Yg])
        p1, p2 = model.stage1.predict(F1), model.stage2.predict(F2)
        if a.edge_scenes:
            model.edge = _edge_stage(model, white, a)
        if a.orphan_scenes:
            model.orphan = _orphan_gate(model, white, a)
        if a.orphan_scorer_scenes:
            model.orphan_score = _orphan_scorer(model, white, a)
        if a.centre_scenes:
            model.centre = _centre_stage(model, white, a)
        model.save(path)
        print(f"{name}: stage 1 {len(Y1)} candidates ({int(Y1.sum())} blobs) recall {(p1[Y1 > 0.5] >= 0.05).mean():.4f} "
              f"at the gate; stage 2 {len(Y2)} fits ({int(Y2.sum())} blobs) recall {(p2[Y2 > 0.5] >= 0.4).mean():.4f}, "
              f"rejection {(p2[Y2 < 0.5] < 0.4).mean():.4f} at 0.4; {time.time() - t:.0f} s -> {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
