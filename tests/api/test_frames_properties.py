"""Property tests of the one upload decoder (:func:`services.uploads.decode_upload`).

Every kind of body a client may send (PLY, PCD, an RGB-D frame's zip archive; valid,
mutated, hostile paths, random bytes) decodes to a fragment or raises a
:class:`~services.errors.FragmentError`, which the front ends map to 413, 415 or 422.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings

from schemas.params import ParserLimits, PipelineParams
from services.errors import FragmentError, InvalidArchiveError
from services.uploads import decode_upload
from tests.fuzzing import FUZZ_MIN_POINTS, PROPERTY, fragment_bodies, seed_frame_files, zip_bytes

pytestmark = pytest.mark.timeout(120)

PARAMS = PipelineParams(parser=ParserLimits(min_points=FUZZ_MIN_POINTS, max_points=100_000))


@settings(PROPERTY, max_examples=400)
@given(data=fragment_bodies())
def test_any_upload_decodes_or_fails_cleanly(data: bytes) -> None:
    try:
        decode_upload(data, PARAMS)
    except FragmentError as exc:
        assert exc.message and exc.code


def test_corrupt_deflate_stream_is_an_invalid_archive() -> None:
    """A zip entry whose deflate data is corrupt (zlib.error, found by the fuzzer) is
    ``invalid_archive``, not an internal error."""
    archive = bytearray(zip_bytes(seed_frame_files()))
    start = archive.index(b"depth.png") + len(b"depth.png")  # the first entry's data
    archive[start : start + 16] = b"\xff" * 16
    with pytest.raises(InvalidArchiveError):
        decode_upload(bytes(archive), PARAMS)
