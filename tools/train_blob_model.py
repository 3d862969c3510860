#!/usr/bin/env python
"""Train the blob-centre classifiers shipped in ``resources/blob_model_{black,white}.npz``.

Examples are generated (``carapost.core.blobs.synth``): markers over varied
skin tone, shading, blur, noise and partial occlusion by the brim, among the
confusers of a face (nostrils, eye corners, brows, hair, brim edges, specular
highlights).  The candidate finder of the detector runs on each image; every
candidate is labelled positive when it lies near a visible marker's centre,
negative when it is away from every marker, and left out when ambiguous.  A
one-hidden-layer tanh network (16 units) is fitted with full-batch Adam on the
class-balanced logistic loss.  Everything is seeded: the same command gives
the same weights.

Usage::

    python tools/train_blob_model.py [--images 160] [--seed 5] [--out resources]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from carapost.core.blobs.detector import as_grey_u8, find_candidates  # noqa: E402
from carapost.core.blobs.model import BlobModel  # noqa: E402
from carapost.core.blobs.synth import render  # noqa: E402


def examples(white: bool, n_images: int, seed: int):
    """Feature rows and labels from ``n_images`` generated images of one colour."""
    rng = np.random.default_rng([seed, int(white)])
    F, Y = [], []
    for i in range(n_images):
        big = i % 4 == 3
        s = render(rng, 360, 480, markers=30 if not big else 12, white=white,
                   radius=(1.8, 7.0) if not big else (6.0, 22.0), confusers=int(rng.integers(3, 12)))
        c, _ = find_candidates(as_grey_u8(s.image), white, 2.0, 60.0)
        if len(c.x) == 0:
            continue
        pts = np.stack([c.x, c.y], 1)
        tol = np.maximum(1.5, 0.75 * 2.0 ** c.level)
        pos = np.zeros(len(pts), bool)
        near = np.zeros(len(pts), bool)
        if len(s.centres):
            d = np.linalg.norm(pts[:, None] - s.centres[None], axis=2)
            j = d.argmin(1)
            dm = d[np.arange(len(pts)), j]
            r = s.axes[j, 0]
            pos = dm <= tol
            # Candidates on a marker's body or edge, off its centre, are neither: the fit recentres them.
            near = ~pos & (dm < r + 2.5)
        if len(s.hidden):
            dh = np.linalg.norm(pts[:, None] - s.hidden[None], axis=2).min(1)
            near |= dh < 8.0
        use = pos | ~near
        F.append(c.feats[use])
        Y.append(pos[use])
    return np.concatenate(F), np.concatenate(Y).astype(np.float32)


def train(F: np.ndarray, Y: np.ndarray, seed: int, hidden: int = 16, iters: int = 3000) -> BlobModel:
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
    return BlobModel(f32(mean), f32(std), f32(W1), f32(c1), f32(W2), float(c2[0]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", type=int, default=160, help="generated training images per colour")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "resources"))
    a = ap.parse_args(argv)
    for white in (False, True):
        t = time.time()
        F, Y = examples(white, a.images, a.seed)
        model = train(F, Y, a.seed)
        p = model.predict(F)
        acc_pos = float((p[Y > 0.5] >= 0.4).mean())
        acc_neg = float((p[Y < 0.5] < 0.4).mean())
        name = "white" if white else "black"
        path = Path(a.out) / f"blob_model_{name}.npz"
        model.save(path)
        print(f"{name}: {len(Y)} examples ({int(Y.sum())} blobs), training recall {acc_pos:.4f}, "
              f"rejection {acc_neg:.4f} at 0.4, {time.time() - t:.0f} s -> {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
