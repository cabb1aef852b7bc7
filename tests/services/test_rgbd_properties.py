"""Property tests of the RGB-D frame decoder: any files give a frame or a frame error.

A valid frame's ``depth.png``, ``intrinsics.json`` and ``color.png`` are mutated, dropped,
replaced by random bytes or by arbitrary intrinsics; :func:`services.rgbd.decode_frame`
must return a consistent frame or raise a :class:`~services.errors.FragmentError`.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

from schemas.params import ParserLimits
from services.errors import FragmentError
from services.rgbd import decode_frame
from tests.fuzzing import FUZZ_MIN_POINTS, PROPERTY, frame_file_sets, seed_frame_files

pytestmark = pytest.mark.timeout(120)

LIMITS = ParserLimits(min_points=FUZZ_MIN_POINTS)


def test_seed_frame_decodes() -> None:
    frame = decode_frame(seed_frame_files(), limits=LIMITS)
    assert frame.shape == (30, 40) and frame.color is not None


@settings(PROPERTY, max_examples=300)
@given(files=frame_file_sets())
def test_mutated_frames_decode_or_fail_cleanly(files: dict[str, bytes]) -> None:
    try:
        frame = decode_frame(files, limits=LIMITS)
    except FragmentError as exc:
        assert exc.message and exc.code
        return
    k = frame.intrinsics
    assert frame.shape == (k.height, k.width)
    assert frame.depth.dtype == np.float32 and np.isfinite(frame.depth).all()
    assert frame.color is None or frame.color.shape == (k.height, k.width, 3)
