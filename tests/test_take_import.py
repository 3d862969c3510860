"""Import Pico Files / CLI INPUT: a project from a take's media."""
import logging

import cv2
import numpy as np
import pytest

from carapost.core.errors import CaraError
from carapost.io import cara
from carapost.io.pico import write_pico
from carapost.io.take import project_from_input, project_from_pico, project_from_sources


def _frames(n, w=64, h=48, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 255, (h, w), dtype=np.uint8) for _ in range(n)]


def test_project_from_pico_take(tmp_path, caplog):
    for ch in range(4):
        write_pico(tmp_path / f"Example_{ch}.pico", _frames(10 if ch != 2 else 8, seed=ch), frame_rate=50.0, channel=ch)
    with caplog.at_level(logging.WARNING, logger="carapost"):
        p = project_from_pico(tmp_path / "Example_2.pico")
    assert p.name == "Example" and p.sensor_count == 4 and p.frame_count == 10 and p.frame_rate == 50.0
    assert [s.frame_count for s in p.sensors] == [10, 10, 8, 10]
    assert p.sensors[3].media.path.endswith("Example_3.pico") and p.sensors[3].media.kind == "pico"
    assert "channel 2 has 8 frames" in caplog.text
    cara.save_project(p, tmp_path / "Example.cara")
    q = project_from_input(tmp_path / "Example.cara")
    assert q.sensors[1].media.path == p.sensors[1].media.path


def test_project_from_image_folders(tmp_path):
    dirs = []
    for ch in range(2):
        d = tmp_path / f"cam{ch}"
        d.mkdir()
        for i, img in enumerate(_frames(5, seed=ch)):
            cv2.imwrite(str(d / f"img{i:03d}.png"), img)
        dirs.append(str(d))
    p = project_from_input(None, dirs)
    assert p.sensor_count == 2 and p.frame_count == 5 and p.sensors[0].media.kind == "images"
    assert (p.sensors[0].width, p.sensors[0].height) == (64, 48)


def test_missing_source_is_named(tmp_path):
    with pytest.raises(CaraError, match="nothing_here"):
        project_from_sources([tmp_path / "nothing_here.pico"])


def test_take_frames_apply_the_image_sequence_offset(tmp_path):
    from carapost.core.document import Document
    from carapost.core.edits import ShiftImageOffset
    from carapost.io.frames import TakeFrames

    frames = {ch: _frames(6, seed=ch) for ch in range(2)}
    for ch in range(2):
        write_pico(tmp_path / f"T_{ch}.pico", frames[ch], channel=ch)
    p = project_from_pico(tmp_path / "T_0.pico")
    tf = TakeFrames(p)
    assert np.array_equal(tf.image(1, 3), frames[1][3])
    Document(p).run(ShiftImageOffset([1]))
    assert np.array_equal(tf.image(1, 3), frames[1][2])
    assert not tf.image(1, 0).any()  # before the channel's first frame: blank
    assert np.array_equal(tf.image(0, 3), frames[0][3])
    p.sensors[0].media.path = str(tmp_path / "gone.pico")
    assert tf.image(0, 3).shape == (48, 64) and not tf.image(0, 3).any()
    tf.close()
