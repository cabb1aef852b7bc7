"""Property tests of the hints parser (:func:`api.hints.parse_hints`, schema in
:mod:`schemas.hints`): any body gives hints or ``invalid_hints``.

Bodies: the valid example, the example with one part replaced by arbitrary JSON or extreme
numbers, arbitrary JSON, deeply nested arrays and objects, mutated text, random bytes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings

from api.errors import InvalidHintsError
from api.hints import parse_hints
from schemas.ids import is_valid_id
from tests.fuzzing import PROPERTY, hints_bodies, seed_hints

pytestmark = pytest.mark.timeout(120)


def test_seed_hints_parse() -> None:
    hints = parse_hints(json.dumps(seed_hints()))
    assert hints.has_priors and hints.order == ["frag_00", "frag_03", "frag_01"]


@settings(PROPERTY, max_examples=500)
@given(body=hints_bodies())
def test_any_body_gives_hints_or_invalid_hints(body: bytes) -> None:
    try:
        hints = parse_hints(body)
    except InvalidHintsError as exc:
        assert exc.code == "invalid_hints" and exc.message.startswith("invalid hints")
        return
    for prior in hints.fragments.values():
        pose = np.asarray(prior.pose)
        assert pose.shape == (4, 4) and np.isfinite(pose).all()
        assert prior.sigma_xy > 0 and prior.sigma_yaw_deg > 0
    ids = [*hints.fragments, *hints.order, *(i for pair in hints.neighbours for i in pair)]
    assert all(is_valid_id(i) for i in ids)
    assert parse_hints(hints.model_dump_json()) == hints  # what is stored reads back
