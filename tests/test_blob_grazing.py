"""Thin dots seen at grazing angles: the generated training images of ``tools/train_blob_model.py --grazing``."""
from __future__ import annotations

import numpy as np

from carapost.core.blobs.synth import GRAZING_KINDS, render_grazing


def test_grazing_images_hold_thin_dots_beside_dark_structures_with_their_truth():
    a = render_grazing(np.random.default_rng(3), white=True, structures=3, markers=0, confusers=0)
    b = render_grazing(np.random.default_rng(3), white=True, structures=3, markers=0, confusers=0)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.centres, b.centres)
    assert len(a.centres) >= 8
    assert (a.axes[:, 1] <= 1.4).all() and (a.axes[:, 1] >= 0.4).all() and (a.axes[:, 0] >= 2.5).all()
    # A dot of the truth is either required or hidden, never both.
    if len(a.hidden):
        assert np.linalg.norm(a.centres[:, None] - a.hidden[None], axis=2).min() > 1.0
    # Against the dark beyond the face's outline (8-40 grey levels before noise) every required white dot
    # stands out: a thin dot's paint is spread by the blur, but its centre is still brighter than the dark.
    for x, y in a.centres:
        assert a.image[int(round(y)), int(round(x))] > 45


def test_each_kind_of_grazing_structure_carries_thin_dots_and_a_hidden_dot_is_not_required():
    for k, kind in enumerate(GRAZING_KINDS):
        # structures=k+1 cycles through the kinds, so the last one drawn is ``kind``.
        s = render_grazing(np.random.default_rng([7, k]), structures=k + 1, dots=6, markers=0, confusers=0)
        assert len(s.centres) >= 3, kind
        assert (s.axes[:, 1] <= 1.4).all(), kind
    # A second outline drawn over dots placed earlier puts them in the dark background beyond it: those are
    # hidden (without that rule 4-8 of ~25 required dots of each of these images would lie in the dark).
    for seed in (0, 1, 2):
        s = render_grazing(np.random.default_rng(seed), white=False, structures=4, dots=12, markers=0, confusers=0)
        assert len(s.hidden) >= 4
        dark = s.image < 50
        for x, y in s.centres:
            assert not dark[int(round(y)) - 1:int(round(y)) + 2, int(round(x)) - 6:int(round(x)) + 7].all(), seed
