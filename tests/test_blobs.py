"""Blob detection: the detector's filters and inputs, and the undoable blob operations."""
from __future__ import annotations

import sys

import cv2
import numpy as np
import pytest

from carapost.core.blob_ops import (blob_preview, detect_blobs_current_frame, detect_blobs_range,
                                    read_blob_parameters_from_pico, remove_unused_detections)
from carapost.core.blobs import detect
from carapost.core.blobs.synth import disc_image, match_truth, render, sample_frames
from carapost.core.commands import UndoStack
from carapost.core.detections import COLOR_BLACK, COLOR_WHITE, make_detections
from carapost.core.errors import CaraError
from carapost.core.points import SRC_DETECTION, SRC_NONE
from carapost.core.progress import Cancelled, Progress
from carapost.core.project import Project
from carapost.core.properties import Properties


#: Floors on one sample-take frame (4 cameras): recall of visible markers within 1.5 px (faint ones,
#: black paint on a dense black brow, are not required), precision, 2-D centre RMS of hits.  The issue's
#: targets are 0.995, 0.98 and 0.08 px; the detector reaches 0.981 / 0.977 (black / white), 0.994 / 0.985
#: and 0.127 / 0.131 px here (docs/blobs.md, "Known limits"; 0.18 / 0.24 px before the edge step), and these
#: floors, a little short of that, catch any loss of accuracy.
RECALL_MIN, PRECISION_MIN, RMS_MAX = 0.97, 0.98, 0.16


def _discs(radii, white=False, size=(240, 320), bg=120, seed=0):
    """Isolated discs of the given radii on flat grey with a little noise, and their centres."""
    rng = np.random.default_rng(seed)
    img = np.full(size, float(bg), np.float32)
    centres = []
    for i, r in enumerate(radii):
        cx, cy = 40 + (i % 5) * 60 + rng.uniform(-0.5, 0.5), 40 + (i // 5) * 60 + rng.uniform(-0.5, 0.5)
        disc, _ = disc_image(rng, 41, r, 1.0, 90.0, 0.0, 0.0, centre=(20 + cx % 1, 20 + cy % 1))
        x0, y0 = int(cx) - 20, int(cy) - 20
        img[y0:y0 + 41, x0:x0 + 41] += disc if white else -disc
        centres.append((cx, cy))
    img += rng.normal(0, 1.5, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), np.array(centres)


def _match(rec, centres, tol=1.5):
    if len(rec) == 0:
        return 0
    d = np.hypot(rec["x"][None, :] - centres[:, 0:1], rec["y"][None, :] - centres[:, 1:2])
    return int((d.min(1) <= tol).sum())


# ------------------------------------------------------------------ detector
def test_finds_black_markers_on_a_face_like_image():
    s = render(np.random.default_rng(3), 360, 480, markers=30, radius=(2.5, 6), noise=(1, 2), confusers=4)
    rec = detect(s.image)
    assert _match(rec, s.centres) >= 0.95 * len(s.centres)
    assert np.all(rec["color"] == COLOR_BLACK)
    d = np.hypot(rec["x"][None, :] - s.centres[:, 0:1], rec["y"][None, :] - s.centres[:, 1:2]).min(1)
    assert np.median(d) < 0.15


def test_centre_accuracy_isolated_disc():
    img, centres = _discs([4.0] * 5)
    rec = detect(img)
    assert len(rec) == 5
    d = np.hypot(rec["x"][None, :] - centres[:, 0:1], rec["y"][None, :] - centres[:, 1:2]).min(1)
    assert d.max() < 0.1
    assert np.allclose(rec["major"], 8.0, atol=0.8) and np.allclose(rec["minor"], 8.0, atol=0.8)


@pytest.mark.parametrize("angle", [0.0, 30.0, -60.0])
def test_ellipse_axes_and_angle_of_an_oblique_dot(angle):
    from carapost.core.blobs.synth import _ellipse_coverage, _paste

    img = np.full((80, 80), 150.0, np.float32)
    cx, cy = 40.3, 39.6
    y0, x0, cov = _ellipse_coverage(80, 80, cx, cy, 6.0, 2.5, np.radians(angle), ss=8)
    _paste(img, y0, x0, cov, 20.0)
    img = cv2.GaussianBlur(img, (0, 0), 0.8) + np.random.default_rng(1).normal(0, 1.0, img.shape)
    rec = detect(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    assert len(rec) == 1
    r = rec[0]
    assert np.hypot(r["x"] - cx, r["y"] - cy) < 0.1
    assert float(r["major"]) == pytest.approx(12.0, rel=0.1) and float(r["minor"]) == pytest.approx(5.0, rel=0.15)
    assert abs((float(r["angle"]) - angle + 90) % 180 - 90) < 3.0


def test_radius_filters_use_the_longest_axis_full_length():
    img, centres = _discs([2.5, 2.5, 2.5, 8.0, 8.0, 8.0])
    small, big = centres[:3], centres[3:]
    rec = detect(img, min_major=4.0, max_major=50.0)
    assert _match(rec, small) == 3 and _match(rec, big) == 3
    rec = detect(img, min_major=10.0, max_major=50.0)          # majors ~5 px are dropped
    assert _match(rec, small) == 0 and _match(rec, big) == 3
    rec = detect(img, min_major=4.0, max_major=10.0)           # majors ~16 px are dropped
    assert _match(rec, small) == 3 and _match(rec, big) == 0


def _large_dots(n=24, seed=3):
    """Images of one large black dot each (semi-major axis 12-24 px, aspect 0.55-1), blurred and noisy."""
    from carapost.core.blobs.synth import _ellipse_coverage

    rng = np.random.default_rng(seed)
    for _ in range(n):
        a = rng.uniform(12, 24)
        b, th = a * rng.uniform(0.55, 1.0), rng.uniform(0, np.pi)
        cx, cy = rng.uniform(90, 110), rng.uniform(90, 110)
        img = np.full((200, 200), 160.0, np.float32)
        y0, x0, cov = _ellipse_coverage(200, 200, cx, cy, a, b, th)
        img[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]] += (25.0 - 160.0) * cov
        img = cv2.GaussianBlur(img, (0, 0), 1.0) + rng.normal(0, 2.0, img.shape)
        yield np.clip(np.rint(img), 0, 255).astype(np.uint8), (cx, cy)


def test_large_dots_are_found_once(monkeypatch):
    """Dots of semi-major axis 12-24 px: the coarse levels' candidates measured apart from the finer ones, on the
    level one octave finer first (``detector.LEVEL_FIRST``), and two fits that step 5 brought to one dot's centre
    kept once."""
    from carapost.core.blobs import detector

    def found(images):
        hits = extra = 0
        for img, (cx, cy) in images:
            rec = detect(img)
            d = np.hypot(rec["x"] - cx, rec["y"] - cy)
            hits += int(np.any(d <= 1.5))
            extra += int(np.sum(d > 1.5)) + max(int(np.sum(d <= 1.5)) - 1, 0)
        return hits, extra

    hits, extra = found(_large_dots())
    assert hits == 24 and extra == 0
    # Measured with the finer candidates, as before: some are missed.
    monkeypatch.setattr(detector, "LEVEL_FIRST", 99)
    assert found(_large_dots())[0] <= 22


def test_threshold_finds_fewer_as_it_rises():
    s = render(np.random.default_rng(4), 360, 480, markers=25, confusers=10)
    n = [len(detect(s.image, threshold=t)) for t in (0.05, 0.4, 0.95)]
    assert n[0] >= n[1] >= n[2]
    assert n[0] > n[2]


def test_black_white_switching():
    img, centres = _discs([4.0] * 4, white=True)
    assert _match(detect(img, white=True), centres) == 4
    assert _match(detect(img, white=False), centres) == 0
    props = Properties()
    assert _match(blob_preview(img, props), centres) == 0          # default: black only
    props.set("blob.find_white_blobs", True)
    rec = blob_preview(img, props)
    assert _match(rec, centres) == 4 and np.all(rec["color"][_near(rec, centres)] == COLOR_WHITE)
    props.set("blob.find_black_blobs", False)
    props.set("blob.find_white_blobs", False)
    assert len(blob_preview(img, props)) == 0


def _near(rec, centres):
    d = np.hypot(rec["x"][:, None] - centres[None, :, 0], rec["y"][:, None] - centres[None, :, 1])
    return d.min(1) <= 1.5


@pytest.mark.parametrize("value", [0, 128, 255])
def test_constant_and_saturated_images_give_nothing(value):
    img = np.full((200, 300), value, np.uint8)
    assert len(detect(img)) == 0 and len(detect(img, white=True)) == 0


def test_saturated_region_gives_no_blobs_inside():
    img, centres = _discs([4.0] * 10, white=True)
    img[:, :160] = 255                                        # left half burnt out
    rec = detect(img, white=True)
    assert np.all(rec["x"] >= 150)


def test_empty_and_bad_images_are_refused_clearly():
    with pytest.raises(CaraError, match="too small"):
        detect(np.zeros((0, 0), np.uint8))
    with pytest.raises(CaraError, match="float32"):
        detect(np.zeros((50, 50), np.float32))
    with pytest.raises(CaraError, match="shape"):
        detect(np.zeros((5, 50, 50), np.uint8))


def test_16bit_and_colour_images_are_converted():
    img, centres = _discs([4.0] * 4)
    ref = detect(img)
    r16 = detect(img.astype(np.uint16) * 257)
    rgb = detect(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    assert len(r16) == len(ref) == len(rgb)
    assert np.allclose(r16["x"], ref["x"]) and np.allclose(rgb["y"], ref["y"])


# ------------------------------------------------------ sample take accuracy
@pytest.fixture(scope="module")
def sample_take():
    """One frame of a ``carapost sample`` take (seed 0, four 1280x720 cameras), black and white markers."""
    return {white: sample_frames(white, seed=0, frames=1) for white in (False, True)}


@pytest.mark.parametrize("white", [False, True], ids=["black", "white"])
def test_accuracy_on_a_sample_take(sample_take, white):
    hits = total = false = 0
    errs = []
    for s in sample_take[white]:
        rec = detect(s.image, white=white)
        hit, f, e = match_truth(np.stack([rec["x"], rec["y"]], 1), s)
        hits, total, false = hits + hit.sum(), total + len(hit), false + f
        errs.append(e)
    e = np.concatenate(errs)
    recall, precision = hits / total, hits / (hits + false)
    rms = float(np.sqrt((e ** 2).sum(1).mean()))
    assert recall >= RECALL_MIN, (recall, precision, rms)
    assert precision >= PRECISION_MIN, (recall, precision, rms)
    assert rms <= RMS_MAX, (recall, precision, rms)


@pytest.mark.parametrize("white", [False, True], ids=["black", "white"])
def test_brim_dots_are_found_at_the_default_threshold(sample_take, white):
    props = Properties()
    props.set(f"blob.find_{'white' if white else 'black'}_blobs", True)
    props.set(f"blob.find_{'black' if white else 'white'}_blobs", False)
    assert props[f"blob.{'white' if white else 'black'}_threshold"] == 0.4
    found = total = 0
    for s in sample_take[white]:
        rec = blob_preview(s.image, props)
        hit, _f, _e = match_truth(np.stack([rec["x"], rec["y"]], 1), s)
        found += hit[s.brim].sum()
        total += s.brim.sum()
    assert total >= 60                       # oblique dots of the brim, seen by all four cameras
    assert found == total


def test_thin_dots_beside_the_face_outline_are_found_from_the_narrower_dog(sample_take):
    """Edge-on black dots 1-3 px inside the face's dark outline (minor semi-axis 0.65-0.85 px).

    On the inverted image the outline's dark background is a bright region beside the dot, and
    the ordinary DoG's response to it covers the dot: its nearest candidate is 1.7-3.3 px off,
    and until the narrower DoG of the finest level (``features.thin_candidates``) none of these
    views was detected.  Seed 0, frame 0: the benchmark's quick frames.  Drawn under perspective (session 24),
    ``Cheek_L_7`` in camera 3 (minor semi-axis 0.65 px) keeps its narrow-DoG candidate, but the edge ellipse
    around it no longer passes (its fit runs 2.3 px into the outline, as before, and is scored 0.035): it is
    required to have its candidate only.
    """
    from carapost.core.blobs.detector import as_grey_u8, find_candidates

    for cam, name in ((0, "Cheek_R_9"), (1, "Cheek_R_9"), (2, "Jaw_L_2"), (3, "Jaw_L_2"), (3, "Cheek_L_7")):
        s = sample_take[False][cam]
        k = s.names.index(name)
        assert s.axes[k, 1] < 0.9, (cam, name, s.axes[k])
        cand, _ = find_candidates(as_grey_u8(s.image), False, 4.0, 50.0)
        d = np.hypot(cand.x - s.centres[k, 0], cand.y - s.centres[k, 1])
        assert d[~cand.thin].min() > 1.5 and d[cand.thin].min() < 1.5, (cam, name)
        if (cam, name) != (3, "Cheek_L_7"):
            rec = detect(s.image)
            assert np.hypot(rec["x"] - s.centres[k, 0], rec["y"] - s.centres[k, 1]).min() < 0.5, (cam, name)
    # Only black dots are looked for so (the face's outline is dark, unlike a white dot).
    cand, _ = find_candidates(as_grey_u8(sample_take[True][0].image), True, 4.0, 50.0)
    assert not cand.thin.any()


@pytest.fixture(scope="module")
def small_take():
    """One frame of a 35-marker sample take (seed 1, four cameras), black and white markers."""
    return {white: sample_frames(white, seed=1, frames=1, markers=35) for white in (False, True)}


@pytest.mark.parametrize("white", [False, True], ids=["black", "white"])
def test_brow_markers_are_found_where_the_paint_shows(small_take, white):
    """The dots painted among the eyebrow's hairs are found where the paint shows.

    White dots show on a black brow everywhere; black paint on the brow's dense middle
    (``Brow_*_2``) changes the image by a few grey levels where other black dots change
    it by ~100, so the truth calls them faint (neither required nor false) and the
    brow's ends (``Brow_*_1``, ``Brow_*_3``) must be found: white ones in every camera, black
    ones in at least three of the four (two make a 3D point).  Black ``Brow_L_1`` touches brow
    hair, which is measured with it (a 19 x 10 px ellipse, 0.9 px off): since stage 2 was
    retrained with the ellipses found from a candidate's own edge, it scores that blob 0.24 in
    camera 1 (0.5-0.8 in the others).  (On other seeds the outer end, ``Brow_*_3``, seen
    obliquely where the brow thins, is still missed in one or two cameras: docs/blobs.md,
    "Known limits".)
    """
    found = {}
    for s in small_take[white]:
        rec = detect(s.image, white=white)
        hit, _f, e = match_truth(np.stack([rec["x"], rec["y"]], 1), s)
        brow = [k for k, n in enumerate(s.names) if n.startswith("Brow_")]
        assert len(brow) == (6 if white else 4), s.names
        for k in brow:
            found[s.names[k]] = found.get(s.names[k], 0) + int(hit[k])
        assert sorted(s.faint_names) == ([] if white else ["Brow_L_2", "Brow_R_2"])
        err = np.hypot(*e.T)
        assert np.median(err) < 0.15
    assert min(found.values()) >= (4 if white else 3), found


def test_a_dot_merged_into_a_candidate_that_went_elsewhere_is_measured_on_its_own():
    """The first round's merge does not lose a clear dot (``detector.fit_candidates``, ``_unclaimed``).

    After the first round, candidates whose answers are within half a minor axis are one blob and
    only the best-centred is measured on.  On these two frames (white, seed 1, frame 0 of the
    81-frame take, cameras 1 and 2) the one kept for ``Jaw_L_4`` and ``Nose_Bridge`` was a coarser candidate whose later
    rounds took in a neighbour and ended elsewhere: with no kept fit left on the dot, the dot's
    own candidate is measured on its own again.  Without that step both fits are not ``ok``
    (stage 2 never sees them) and both clear dots are missed.
    """
    from carapost.core.blobs import detector as D
    from carapost.core.blobs.model import default_model

    for s, name in zip(sample_frames(True, seed=1, frames=2, step=80, cameras=(1, 2)), ("Jaw_L_4", "Nose_Bridge")):
        cx, cy = s.centres[list(s.names).index(name)]
        cand, bright = D.find_candidates(s.image, True, 4.0, 50.0)
        fit = D.fit_stage(cand, bright, default_model(True))
        d = np.hypot(fit.x - cx, fit.y - cy)
        assert (fit.ok & (d < 0.3)).any(), name
        rec = detect(s.image, white=True)
        assert np.hypot(rec["x"] - cx, rec["y"] - cy).min() < 0.3, name


# -------------------------------------------------------------- operations
@pytest.fixture
def take(tmp_path):
    """A 2-sensor, 4-frame take of image folders with black markers."""
    from carapost.io.take import project_from_sources

    rng = np.random.default_rng(7)
    dirs = []
    for s in range(2):
        d = tmp_path / f"cam{s}"
        d.mkdir()
        for f in range(4):
            img, _c = _discs([4.0] * 6, seed=10 * s + f)
            cv2.imwrite(str(d / f"{f:04d}.png"), img)
        dirs.append(str(d))
    del rng
    return project_from_sources(dirs)


def test_detect_current_frame_and_undo(take):
    before = take.digest()
    stack = UndoStack(take)
    cmd = detect_blobs_current_frame(take, 1)
    assert take.digest() == before                            # computed, not applied
    stack.push(cmd)
    assert take.detections[0].count(1) == 6 and take.detections[1].count(1) == 6
    assert take.detections[0].detected[1] and not take.detections[0].detected[0]
    stack.undo()
    assert take.digest() == before
    stack.redo()
    assert take.detections[1].count(1) == 6


def test_detect_range_honours_channel_selection_and_undo(take):
    take.channel_selection = [1]
    before = take.digest()
    stack = UndoStack(take)
    stack.push(detect_blobs_range(take, 0, 3, workers=2))
    assert [take.detections[1].count(f) for f in range(4)] == [6] * 4
    assert take.detections[0].total() == 0
    stack.undo()
    assert take.digest() == before


def test_detect_range_cancel_leaves_project_untouched(take):
    before = take.digest()
    prog = Progress()
    prog._callback = lambda done, total, msg: prog.cancel() if done >= 1 else None
    with pytest.raises(Cancelled):
        detect_blobs_range(take, 0, 3, progress=prog, workers=1)
    assert take.digest() == before
    prog = Progress()
    prog._callback = lambda done, total, msg: prog.cancel() if done >= 2 else None
    with pytest.raises(Cancelled):
        detect_blobs_range(take, 0, 3, progress=prog, workers=2)
    assert take.digest() == before


@pytest.fixture
def pico_take(tmp_path):
    """A 2-channel ``.pico`` take of 30 frames (I-frame every 8) with black discs that move."""
    from carapost.io.pico import write_pico
    from carapost.io.take import project_from_input

    for ch in range(2):
        frames = [_discs([4.0] * 4, seed=100 * ch + f, size=(160, 320))[0] for f in range(30)]
        write_pico(tmp_path / f"Runs_{ch}.pico", frames, channel=ch, gop=8)
    return project_from_input(tmp_path / "Runs_0.pico", None)


def test_range_workers_decode_their_own_runs(pico_take, monkeypatch):
    """Detect Blobs [Active Range] on pico media: runs start at I-frames, and two workers detect what one does."""
    from carapost.core import blob_ops
    from carapost.io.media import open_source

    src = open_source(pico_take.sensors[0].media.path)
    runs = blob_ops._runs(src, 3, 29, size=10)
    assert list(src.keyframes) == [0, 8, 16, 24]
    src.close()
    # Contiguous, covering 3..28; every run after the first starts at the I-frame at or before 13, 23.
    assert runs == [(3, 8), (8, 16), (16, 29)]
    monkeypatch.setattr(blob_ops, "RUN_FRAMES", 10)
    one = detect_blobs_range(pico_take, 0, 29, workers=1).cells
    two = detect_blobs_range(pico_take, 0, 29, workers=2).cells
    assert sorted(one) == sorted(two) == [(s, f) for s in range(2) for f in range(30)]
    assert all(np.array_equal(one[k], two[k]) for k in one)
    assert sum(len(v) for v in one.values()) >= 2 * 30 * 4
    # The frames the workers decoded (one decoder thread each) are the file's: the same detections as on
    # frames read one by one with the default decoder.
    from carapost.core.blobs import detect_with_properties

    src = open_source(pico_take.sensors[1].media.path)
    for f in (0, 7, 8, 29):
        assert np.array_equal(detect_with_properties(src.read(f), pico_take.properties), one[(1, f)])
    src.close()


def test_a_failing_run_stops_the_range_and_leaves_the_project_untouched(pico_take, monkeypatch):
    from carapost.core import blob_ops

    monkeypatch.setattr(blob_ops, "RUN_FRAMES", 10)
    real = blob_ops.detect_with_settings
    seen = []

    def failing(img, settings):
        seen.append(1)
        if len(seen) == 5:
            raise CaraError("frame 4: cannot be read")
        return real(img, settings)

    monkeypatch.setattr(blob_ops, "detect_with_settings", failing)
    before = pico_take.digest()
    with pytest.raises(CaraError, match="cannot be read"):
        detect_blobs_range(pico_take, 0, 29, workers=2)
    assert pico_take.digest() == before
    assert len(seen) < 2 * 30          # the runs not started were dropped: the take was not detected to its end


def test_redetect_keeps_attachments_within_1px(take):
    stack = UndoStack(take)
    stack.push(detect_blobs_current_frame(take, 2, sensors=[0]))
    rec = take.detections[0].frame(2)
    pt = take.new_point()
    pt.src[2, 0], pt.det[2, 0], pt.uv[2, 0] = SRC_DETECTION, 3, (rec[3]["x"], rec[3]["y"])
    far = take.new_point(point_id=pt.id + 1)
    far.src[2, 0], far.det[2, 0] = SRC_DETECTION, 4
    from carapost.core.edits import AddPoints
    stack.push(AddPoints([pt, far]))
    # A new set where detection 3 moved 0.3 px and detection 4 moved 5 px, order shuffled.
    new = rec.copy()[::-1]
    new["x"][-4] += 0.3
    new["x"][-5] += 5.0
    before = take.digest()
    from carapost.core.blob_ops import DetectBlobs
    stack.push(DetectBlobs({(0, 2): new}))
    p, q = take.points[pt.id], take.points[far.id]
    assert p.src[2, 0] == SRC_DETECTION and p.det[2, 0] == len(new) - 4
    assert p.uv[2, 0, 0] == pytest.approx(float(new["x"][len(new) - 4]))
    assert q.src[2, 0] == SRC_NONE and q.det[2, 0] == -1
    stack.undo()
    assert take.digest() == before


def test_remove_unused_detections_remaps_and_undoes():
    prj = Project(5, 2)
    prj.detections[0].set_frame(1, make_detections(np.arange(5.0), np.zeros(5)))
    prj.detections[0].set_frame(2, make_detections(np.arange(3.0), np.ones(3)))
    prj.detections[1].set_frame(1, make_detections(np.arange(4.0), np.zeros(4)))
    p = prj.new_point()
    p.src[1, 0], p.det[1, 0] = SRC_DETECTION, 3
    p.src[1, 1], p.det[1, 1] = SRC_DETECTION, 0
    prj.add_point(p)
    q = prj.new_point()
    q.src[1, 0], q.det[1, 0] = SRC_DETECTION, 1
    prj.add_point(q)
    before = prj.digest()
    stack = UndoStack(prj)
    cmd = remove_unused_detections(prj)
    stack.push(cmd)
    assert prj.detections[0].count(1) == 2 and prj.detections[0].count(2) == 0 and prj.detections[1].count(1) == 1
    assert p.det[1, 0] == 1 and q.det[1, 0] == 0 and p.det[1, 1] == 0
    assert prj.detections[0].frame(1)[p.det[1, 0]]["x"] == 3.0
    assert len(cmd._old_cells) == 3                           # only the frames that change are stored
    stack.undo()
    assert prj.digest() == before
    stack.redo()
    assert p.det[1, 0] == 1


def test_read_blob_parameters_from_pico_and_undo():
    prj = Project(3, 1)
    prj.properties.set("blob.black_threshold", 0.9)
    prj.properties.set("blob.find_white_blobs", True)
    stack = UndoStack(prj)
    before = prj.digest()
    stack.push(read_blob_parameters_from_pico(prj))           # no pico parameters: defaults
    assert prj.properties["blob.black_threshold"] == 0.4 and prj.properties["blob.find_white_blobs"] is False
    stack.undo()
    assert prj.digest() == before
    prj.pico_blob_parameters = {"blob.white_threshold": "0.7", "blob.find_white_blobs": "true"}
    stack.push(read_blob_parameters_from_pico(prj))
    assert prj.properties["blob.white_threshold"] == 0.7 and prj.properties["blob.find_white_blobs"] is True


def test_cli_detect_blobs_and_csv(take, tmp_path):
    from carapost.blob_cli import add_blob_commands
    import argparse

    ap = argparse.ArgumentParser()
    add_blob_commands(ap.add_subparsers())
    srcs = [take.sensors[0].media.path, take.sensors[1].media.path]
    out = tmp_path / "t.cara"
    args = ap.parse_args(["detect-blobs", "--sources", *srcs, "-o", str(out), "--end", "1",
                          "--set", "blob.black_threshold=0.3"])
    assert args.func(args) == 0
    csv_path = tmp_path / "d.csv"
    args = ap.parse_args(["detections", str(out), "-o", str(csv_path)])
    assert args.func(args) == 0
    lines = csv_path.read_text().splitlines()
    assert lines[0] == "frame,sensor,x,y,major,minor,angle,color,score"
    rows = [ln.split(",") for ln in lines[1:]]
    assert all(len(r) == 9 for r in rows)
    assert {(r[0], r[1]) for r in rows} == {("0", "0"), ("0", "1"), ("1", "0"), ("1", "1")}
    assert 2 * 2 * 6 <= len(rows) <= 2 * 2 * 6 + 2       # 6 discs per image (a stray at threshold 0.3)
    args = ap.parse_args(["detect-blobs", "--sources", *srcs, "--set", "blob.nope=1"])
    with pytest.raises(CaraError):
        args.func(args)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only (keep_freed_memory)")
def test_range_detection_stops_the_page_faults_of_each_frame(tmp_path):
    """Detect Blobs [Active Range] keeps freed memory: a frame's ~1 MB images are reused, not faulted in again.

    Each run is a fresh process (the C heap's state is the process's); the frames
    are rendered here, as a process that decodes them would not have freed large
    blocks beforehand (that alone raises glibc's thresholds for a while).
    """
    import subprocess
    import textwrap

    np.save(tmp_path / "frames.npy", np.stack([s.image for s in sample_frames(False, seed=0, frames=1)]))
    code = textwrap.dedent("""
        import resource, sys
        import numpy as np
        from carapost.core.blob_ops import detect_frames
        from carapost.core.properties import Properties

        imgs = list(np.load(sys.argv[2]))
        import ctypes
        from carapost.core import heap
        # Both runs start from glibc's documented limits, held fixed: left alone, glibc raises them to
        # the largest block freed so far, so whether each frame's images are mapped again depends on
        # what the process freed before (since the measurement's padded copy of the frame went, often
        # nothing), and the comparison would say nothing about keep_freed_memory().
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(heap._M_MMAP_THRESHOLD, 128 << 10)
        libc.mallopt(heap._M_TRIM_THRESHOLD, 128 << 10)
        if sys.argv[1] == "default":
            heap._done = True                                           # as if keep_freed_memory were never called
        detect_frames(enumerate(imgs), Properties(), workers=1)         # warm up
        f = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        detect_frames(enumerate(imgs * 2), Properties(), workers=1)
        print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f) / (2 * len(imgs)))
    """)
    per_frame = {}
    for mode in ("default", "kept"):
        out = subprocess.run([sys.executable, "-c", code, mode, str(tmp_path / "frames.npy")], capture_output=True,
                             text=True, check=True)
        per_frame[mode] = float(out.stdout.split()[-1])
    assert per_frame["default"] > 100, per_frame       # the images of each frame, faulted in again
    assert per_frame["kept"] < 0.1 * per_frame["default"], per_frame


def test_sample_frames_can_be_taken_where_the_jaw_is_open_widest():
    from carapost.sample.face import EXPRESSIONS
    from carapost.sample.scene import build_scene

    frames = sample_frames(False, seed=3, jaw_open=2, markers=35, cameras=(1,))
    assert len(frames) == 2
    jaw = build_scene(markers=35, frames=120, seed=3).motion.weights[:, EXPRESSIONS.index("jaw_open")]
    widest = int(np.argmax(jaw))
    # The two frames are the widest and the one before; the truth follows the jaw down.
    lips = [i for i, n in enumerate(frames[0].names) if n.startswith("Lip_Lower")]
    assert lips and jaw[widest - 1] > 0.8 * jaw.max()
    closed = sample_frames(False, seed=3, frames=1, markers=35, cameras=(1,))[0]
    y_open = {n: c[1] for n, c in zip(frames[1].names, frames[1].centres)}
    y_closed = {n: c[1] for n, c in zip(closed.names, closed.centres)}
    both = [n for n in y_open if n.startswith("Lip_Lower") and n in y_closed]
    assert both and all(y_open[n] > y_closed[n] + 10 for n in both)


def test_the_classifier_finds_the_dots_of_an_open_jaw():
    """Lower-lip and chin dots at grazing angles in the jaw's shadow, beside the teeth (held-out seeds 3, 4).

    The classifier trained without jaw-open frames found 95.0 % of the visible markers on these frames
    (0.949 and 0.952); trained with them (``tools/train_blob_model.py --jaw-scenes 6``), 95.9 %.
    """
    hit = req = false = 0
    for seed in (3, 4):
        for t in sample_frames(False, seed=seed, jaw_open=1, markers=100):
            rec = detect(t.image)
            h, f, _ = match_truth(np.column_stack([rec["x"], rec["y"]]), t)
            hit, req, false = hit + h.sum(), req + len(h), false + f
    assert hit / req >= 0.955, hit / req
    assert false <= 0.03 * req
