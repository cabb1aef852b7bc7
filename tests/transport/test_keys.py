"""Zenoh key expressions: built and parsed under one prefix."""

from __future__ import annotations

import pytest

from transport.keys import ZenohKeys

pytestmark = pytest.mark.timeout(10)


def test_keys_parse_only_their_own_shapes() -> None:
    keys = ZenohKeys("fleet/a")
    assert keys.parse_fragment(keys.fragment("s", "f")) == ("s", "f")
    assert keys.parse_fragment("fpj/sites/s/fragments/f") is None
    assert keys.parse_fragment(keys.result("s")) is None
    assert keys.parse_result(keys.all_results) == "*"
    assert keys.parse_robot(keys.robot("r-1")) == "r-1"
    assert keys.parse_robot("fleet/a/robots/bad$id") is None
