"""Automatic tracking (issue 7): Track Forwards/Backwards [Sequence]/[Single Frame].

Modules: :mod:`.api` (the operations, returning one undoable command),
:mod:`.engine` (one frame of tracking on arrays), :mod:`.geometry` (fast
corrected-pixel projection, triangulation and pose refinement; its compiled loops
in :mod:`.geometry_kernel`), :mod:`.nearest` (the frame's nearest-detection index), :mod:`.assign`
(candidate search and one-to-one matching), :mod:`.vote` (the region's vote on
a displacement when it changes speed at once), :mod:`.elastic` (neighbour
prediction), :mod:`.patch` (grey-level patches), :mod:`.params`,
:mod:`.synthetic_take` (moving synthetic takes with truth, for tests and
benchmarks) and :mod:`.evaluate` (scoring against the truth).
"""
from .api import track, track_backwards_sequence, track_forwards_sequence, track_single_frame, warm_up
from .params import TrackingParams

__all__ = ["track", "track_forwards_sequence", "track_backwards_sequence", "track_single_frame",
           "TrackingParams", "warm_up"]
