"""The robot-side client's options and attachment, without a session (the commands against a
running service: tests/zenoh/test_robots.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from api.zenoh.ingest import attachment_prior, parse_tag
from robot.client import robot_options
from schemas.hints import FragmentPrior

pytestmark = pytest.mark.timeout(10)


def test_options_split_the_endpoints_and_refuse_a_router() -> None:
    options = robot_options(["tcp/10.0.0.1:7447, tcp/10.0.0.2:7447", " ", "udp/h:1"])
    assert options.zenoh.connect == ["tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447", "udp/h:1"]
    assert options.zenoh.mode == "peer" and options.zenoh.listen == []
    assert options.keys.fragment("lab", "f1") == "fpj/sites/lab/fragments/f1"
    assert robot_options([], prefix="fleet").keys.service == "fleet/service"
    with pytest.raises(ValueError, match="peer or client"):
        robot_options([], mode="router")


def test_the_attachment_is_what_the_service_reads() -> None:
    assert robot_options([]).attachment() is None  # nothing to say: no attachment at all
    options = robot_options([], robot_id="r1", token="secret")
    tag = parse_tag(options.attachment())
    assert (tag.robot_id, tag.token) == ("r1", "secret")
    prior = FragmentPrior(pose=np.eye(4).tolist(), sigma_xy=0.5)
    attachment = options.attachment(prior)
    assert attachment is not None and json.loads(attachment)["robot_id"] == "r1"
    assert attachment_prior(attachment) == prior
