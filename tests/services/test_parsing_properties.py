"""Property tests of the fragment parsers: any bytes give points or a fragment error.

Valid PLY and PCD files are mutated (truncated, bytes flipped, header counts replaced by
huge, negative or non-numeric values, header lines swapped) and random bytes are thrown
in; :func:`services.parsing.parse_fragment` must return finite points or raise a
:class:`~services.errors.FragmentError`, never anything else.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from schemas.params import ParserLimits
from services.errors import FragmentError, FragmentTooLargeError
from services.parsing import parse_fragment
from tests.fuzzing import FUZZ_MIN_POINTS, PROPERTY, cloud_files, seed_clouds

pytestmark = pytest.mark.timeout(120)

LIMITS = ParserLimits(min_points=FUZZ_MIN_POINTS, max_points=100_000)


def _parse_or_fragment_error(data: bytes) -> None:
    try:
        parsed = parse_fragment(data, LIMITS)
    except FragmentError as exc:
        assert exc.message and exc.code
        return
    assert parsed.points.ndim == 2 and parsed.points.shape[1] == 3
    assert parsed.points.dtype == np.float64 and parsed.points.flags.c_contiguous
    assert len(parsed.points) >= LIMITS.min_points
    assert np.isfinite(parsed.points).all()
    assert parsed.format in ("ply", "pcd")


@pytest.mark.parametrize("name", sorted(seed_clouds()))
def test_seed_files_parse(name: str) -> None:
    parsed = parse_fragment(seed_clouds()[name], LIMITS)
    assert len(parsed.points) == 149 and parsed.dropped_nonfinite == 1


@settings(PROPERTY, max_examples=400)
@given(data=cloud_files())
def test_mutated_clouds_parse_or_fail_cleanly(data: bytes) -> None:
    _parse_or_fragment_error(data)


@settings(PROPERTY, max_examples=200)
@given(data=st.binary(max_size=2000))
def test_random_bytes_parse_or_fail_cleanly(data: bytes) -> None:
    _parse_or_fragment_error(data)


@settings(PROPERTY, max_examples=100)
@given(count=st.integers(LIMITS.max_points + 1, 2**80), pcd=st.booleans())
def test_huge_declared_counts_are_refused_before_allocating(count: int, pcd: bool) -> None:
    if pcd:
        header = f"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS {count}\nDATA binary\n"
    else:
        header = (
            f"ply\nformat binary_little_endian 1.0\nelement vertex {count}\n"
            "property float x\nproperty float y\nproperty float z\nend_header\n"
        )
    with pytest.raises(FragmentTooLargeError):
        parse_fragment(header.encode() + b"\x00" * 12, LIMITS)
