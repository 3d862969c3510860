"""Track Backwards from the last frame (issue 7): the sample take's seeds on a chosen frame."""
import json

import numpy as np
import pytest

from carapost.core.errors import CaraError
from carapost.sample import write_sample
from carapost.sample.take import seeds_of_take

SMALL = dict(markers=35, frames=4, seed=1, width=640, height=360, workers=1)


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    d = tmp_path_factory.mktemp("last")
    write_sample(d, seeds_frame=-1, **SMALL)
    return d


def clicks_off_px(seeds: dict, truth: dict) -> np.ndarray:
    """Each click's distance (px) from the clicked marker's true centre on the seeds' frame."""
    f = seeds["frame"]
    labels = [str(v) for v in truth["labels"]]
    nf = len(labels)
    out = []
    for e in seeds["face"]:
        m = labels.index(e["label"])
        out += [np.hypot(*(np.array(uv) - truth["uv"][f, int(c), m])) for c, uv in e["uv"].items()]
    for e in seeds["brim"]:
        out += [np.hypot(*(np.array(uv) - truth["uv"][f, int(c), nf + e["index"]])) for c, uv in e["uv"].items()]
    return np.array(out)


def test_seeds_are_clicked_on_the_chosen_frame(take):
    truth = dict(np.load(take / "truth.npz"))
    seeds = json.loads((take / "seeds.json").read_text())
    assert seeds["frame"] == 3
    assert len(seeds["face"]) == 8 and len(seeds["brim"]) == 6
    # Hand error only (0.5 px, at most 3 sigma, clicks rounded to 0.001 px), on the last frame's markers.
    off = clicks_off_px(seeds, truth)
    assert off.max() <= 1.51
    # An already written take gives the same clicks on any frame without rendering it again.
    assert seeds_of_take(take, -1) == seeds
    first = seeds_of_take(take, 0)
    assert first["frame"] == 0 and clicks_off_px(first, truth).max() <= 1.51 and first != dict(seeds, frame=0)


def test_a_seeds_frame_outside_the_take_is_refused(take, tmp_path):
    with pytest.raises(CaraError, match="seeds-frame"):
        seeds_of_take(take, 4)
    with pytest.raises(CaraError, match="seeds-frame"):
        write_sample(tmp_path, seeds_frame=-5, **SMALL)
