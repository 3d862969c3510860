"""The blob classifier: tiny multilayer perceptrons, two stages and an edge stage.

Stage 1 scores every candidate from its pyramid-level neighbourhood
(:data:`~.features.FEATURE_NAMES`), cheaply, so that only plausible blobs
are measured.  Stage 2 scores measured blobs from what the measurement reveals
(:data:`FIT_FEATURE_NAMES`: how well the gradient lines meet, edge sharpness — paint
has sharp edges, nostrils and shading do not — background residual and slope,
contrast-to-noise, size, elongation, depth — the contrast as a share of the skin's
light: black paint takes ~90 % of it, a mole or a pore a third — and the uniformity of
the blob's core — a pupil has glints in it — and whether the ellipse came from the candidate's own
edge, its measurement having been drawn off it) together with the stage-1 logit.  The
stage-2 probability is the detection's score and what the Black/White
Threshold applies to — except for an ellipse found from its candidate's own edge (its
intensity measurement having been drawn off it), which the **edge stage**, a third network
trained on such ellipses alone, scores from the same features, stage 2's logit and how the edge
looked (:data:`EDGE_FEATURE_NAMES`: how far its points scatter about the ellipse, how many of the
rays found it, how strong it is against the noise and the blob's contrast, and its weakest ray).
A fourth network, the **centre stage** (:class:`~.centre_net.CentreNet`, step 9), reads how far each
kept detection's centre is off from the grey levels about it.

Weights live in ``resources/blob_model_{black,white}.npz`` and are produced by
``tools/train_blob_model.py`` (deterministic seed).  Evaluation is a few small
matrix products, numpy only.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CaraError
from . import centre_net
from .centre_net import CentreNet
from .features import FEATURE_NAMES

RESOURCE_DIR = Path(__file__).resolve().parents[3] / "resources"
#: Features of a measured blob seen by stage 2 (after the stage-1 logit; see :mod:`.centre`).
FIT_FEATURE_NAMES = ("s1_logit", "log_cnr", "log_major", "axis_ratio", "line_rms", "log_sharpness",
                     "border_std", "slope", "fill", "edge_share", "moved", "depth", "core_std", "from_edge")
#: How the edge of an ellipse found from its candidate's edge looked (the edge stage's own inputs,
#: :func:`.detector._edge_quality`).
EDGE_FEATURE_NAMES = ("edge_scatter", "edge_rays", "log_edge_noise", "edge_contrast", "edge_weakest")
#: What the orphan gate sees of a threshold component about a candidate no believed fit explains
#: (:func:`.detector.orphan_features`): its area (log), semi-axes, axis ratio and fill, its height over the
#: threshold at which it merged (in the image's noise), its peak grey level (a 255th), the noise (log), and its
#: candidate's stage-1 logit, radius, whether it is a narrower-DoG candidate, and stage 1's features.
ORPHAN_FEATURE_NAMES = ("log_area", "comp_a", "comp_b", "comp_ratio", "comp_fill", "height", "peak", "log_noise",
                        "s1_logit", "radius", "thin") + FEATURE_NAMES
#: Stage-1 probability below which a candidate is not measured at all.
STAGE1_GATE = 0.15


@dataclass
class MLP:
    """Standardisation plus one tanh hidden layer and a logistic output."""

    mean: np.ndarray
    std: np.ndarray
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: float

    def logit(self, F: np.ndarray) -> np.ndarray:
        if len(F) == 0:
            return np.zeros(0, np.float32)
        z = (F - self.mean) / self.std
        h = np.tanh(z @ self.w1 + self.b1)
        return (h @ self.w2 + self.b2).astype(np.float32)

    def predict(self, F: np.ndarray) -> np.ndarray:
        """Probability (0-1) of each feature row being a blob."""
        return (1.0 / (1.0 + np.exp(-np.clip(self.logit(F), -30, 30)))).astype(np.float32)

    def arrays(self, prefix: str) -> dict:
        return {prefix + k: v for k, v in dict(mean=self.mean, std=self.std, w1=self.w1, b1=self.b1, w2=self.w2,
                                               b2=np.float32(self.b2)).items()}

    @classmethod
    def from_arrays(cls, z, prefix: str) -> "MLP":
        f32 = lambda k: np.asarray(z[prefix + k], np.float32)  # noqa: E731
        return cls(f32("mean"), f32("std"), f32("w1"), f32("b1"), f32("w2"), float(z[prefix + "b2"]))


@dataclass
class BlobModel:
    """The stages for one blob colour."""

    stage1: MLP
    stage2: MLP | None = None
    #: Scores the ellipses found from a candidate's own edge (``from_edge``) beside stage 2, from stage 2's
    #: features and logit and the edge's own features (:meth:`edge_features`, :meth:`score`); None: stage 2
    #: less :data:`.detector.RESCUE_LOGIT` alone.
    edge: MLP | None = None
    #: Step 9's correction of the kept detections' centres (:mod:`.centre_net`); None: none.
    centre: CentreNet | None = None
    #: The orphan gate: which threshold components about candidates no believed fit explains are worth step 5's
    #: edge search (logit >= 0; :func:`.detector._with_orphans`), from :data:`ORPHAN_FEATURE_NAMES`; None: all.
    orphan: MLP | None = None
    #: Scores the orphan search's fits (:meth:`orphan_scores`) from the edge stage's inputs, trained on such fits
    #: alone (white, session 44); None: they are scored as the rescue's ellipses are (:meth:`score`).
    orphan_score: MLP | None = None

    def save(self, path) -> None:
        arrays = self.stage1.arrays("s1_")
        if self.stage2 is not None:
            arrays.update(self.stage2.arrays("s2_"))
        if self.edge is not None:
            arrays.update(self.edge.arrays("se_"))
        if self.orphan_score is not None:
            arrays.update(self.orphan_score.arrays("sq_"))
        if self.orphan is not None:
            arrays.update(self.orphan.arrays("so_"))
            arrays["orphan_feature_names"] = np.array(ORPHAN_FEATURE_NAMES)
        if self.centre is not None:
            arrays.update(self.centre.arrays("sc_"))
            arrays["centre_grid"] = np.array([centre_net.GRID, centre_net.MARGIN, centre_net.N_INPUTS], np.float64)
        np.savez(path, feature_names=np.array(FEATURE_NAMES), fit_feature_names=np.array(FIT_FEATURE_NAMES),
                 edge_feature_names=np.array(EDGE_FEATURE_NAMES), **arrays)

    @classmethod
    def load(cls, path) -> "BlobModel":
        try:
            z = np.load(path)
            names = tuple(str(n) for n in z["feature_names"])
            fit_names = tuple(str(n) for n in z["fit_feature_names"]) if "fit_feature_names" in z else ()
            edge_names = tuple(str(n) for n in z["edge_feature_names"]) if "edge_feature_names" in z else ()
        except (OSError, ValueError, KeyError) as e:
            raise CaraError(f"{path}: cannot read blob model ({e})") from None
        if names != FEATURE_NAMES or (fit_names and fit_names != FIT_FEATURE_NAMES) or (
                "se_w1" in z and edge_names != EDGE_FEATURE_NAMES):
            raise CaraError(f"{path}: blob model was trained on other features; run tools/train_blob_model.py")
        centre = None
        if "sc_w1" in z:
            grid = tuple(float(v) for v in z["centre_grid"]) if "centre_grid" in z else ()
            if grid != (centre_net.GRID, centre_net.MARGIN, centre_net.N_INPUTS):
                raise CaraError(f"{path}: the blob model's centre stage was trained on another grid; "
                                "run tools/train_blob_model.py --centre-only")
            centre = CentreNet.from_arrays(z, "sc_")
        s2 = MLP.from_arrays(z, "s2_") if "s2_w1" in z else None
        se = MLP.from_arrays(z, "se_") if "se_w1" in z else None
        so = None
        if "so_w1" in z:
            if tuple(str(n) for n in z["orphan_feature_names"]) != ORPHAN_FEATURE_NAMES:
                raise CaraError(f"{path}: the blob model's orphan gate was trained on other features; "
                                "run tools/train_blob_model.py --orphan-only")
            so = MLP.from_arrays(z, "so_")
        sq = MLP.from_arrays(z, "sq_") if "sq_w1" in z else None
        return cls(MLP.from_arrays(z, "s1_"), s2, se, centre, so, sq)

    def edge_features(self, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """The edge stage's inputs: stage 2's features ``F``, stage 2's logit of them and how the edge
        looked (``Q``, :data:`EDGE_FEATURE_NAMES`)."""
        return np.concatenate([F, self.stage2.logit(F)[:, None].astype(np.float32), np.asarray(Q, np.float32)],
                              axis=1)

    def orphan_scores(self, F: np.ndarray, Q: np.ndarray, rescue_logit: float) -> np.ndarray:
        """The scores of the orphan search's fits (stage-2 features ``F``, edge features ``Q``): the orphan scorer's,
        or without one as the rescue's ellipses are scored (:meth:`score`)."""
        if self.orphan_score is None:
            return self.score(F, np.ones(len(F), bool), rescue_logit, Q)
        return self.orphan_score.predict(self.edge_features(F, Q))

    def score(self, F: np.ndarray, from_edge: np.ndarray | None, rescue_logit: float,
              Q: np.ndarray | None = None) -> np.ndarray:
        """The detections' scores: stage 2's probability, and for ellipses found from an edge the larger of
        stage 2's logit less ``rescue_logit`` and the edge stage's (from ``Q``, the rows' edge features;
        without it, or without an edge stage, the rule alone).

        The edge stage only adds: an edge ellipse stage 2 is sure of keeps that score (a white nose tip's
        dot on its soft highlight looks to the edge stage like a specular highlight).
        """
        prob = self.stage2.predict(F)
        if from_edge is None or not from_edge.any():
            return prob
        q = np.clip(prob[from_edge], 1e-9, 1 - 1e-9)
        rule = 1.0 / (1.0 + np.exp(rescue_logit - np.log(q / (1.0 - q))))
        if self.edge is not None and Q is not None:
            rule = np.maximum(rule, self.edge.predict(self.edge_features(F[from_edge], Q[from_edge])))
        prob[from_edge] = rule
        return prob


@functools.lru_cache(maxsize=4)
def default_model(white: bool) -> BlobModel:
    """The shipped model for white (True) or black (False) blobs."""
    path = RESOURCE_DIR / f"blob_model_{'white' if white else 'black'}.npz"
    if not path.exists():
        raise CaraError(f"{path} is missing; run tools/train_blob_model.py")
    return BlobModel.load(path)
