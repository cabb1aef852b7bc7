"""The frames' wrong chains: judged in the floor plan, listed in world coordinates."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.frame_chains import describe, main, wrong_chains
from bench.rgbd_frames import cached_scenes
from bench.scoring import chain_error_in_plan
from services.model_export import to_site

pytestmark = pytest.mark.timeout(120)


def test_a_chain_is_judged_in_the_floor_plan_not_by_its_height() -> None:
    # A fragment turned 90 degrees about z and lifted 1.2 m: local x is world y.
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    pose[2, 3] = 1.2
    truth = {"pose": pose.tolist(), "keypoints_local": [[0.0, 0.0, -1.2], [2.0, 0.0, -1.2]]}
    same = np.array(truth["keypoints_local"])
    assert chain_error_in_plan(same, truth) == pytest.approx(0.0)
    # A wrong floor height is no error in plan; a shift along the floor is.
    assert chain_error_in_plan(same + np.array([0.0, 0.0, 0.3]), truth) == pytest.approx(0.0)
    assert chain_error_in_plan(same + np.array([0.0, 0.1, 0.0]), truth) == pytest.approx(0.1)
    assert chain_error_in_plan(np.zeros((0, 3)), truth) == np.inf


def test_a_frame_whose_chain_was_moved_is_listed_in_world_coordinates(
    capsys: pytest.CaptureFixture[str],
) -> None:
    [scene] = cached_scenes(1, 1000)
    total, before = wrong_chains([scene])
    assert total == len(scene.truth["fragments"])
    # Move one right frame's chain 1 m along its own floor: it is now listed, its truth as
    # the generator drew it.
    fragment = next(f for f in scene.truth["fragments"] if f["id"] not in {w.frame for w in before})
    layout = scene.layouts[fragment["id"]]
    moved = dataclasses.replace(layout, keypoints=layout.keypoints + np.array([1.0, 0.0]))
    shifted = dataclasses.replace(scene, layouts={**scene.layouts, fragment["id"]: moved})
    _, after = wrong_chains([shifted])
    [listed] = [w for w in after if w.frame == fragment["id"]]
    # It was within the threshold of the truth before the move (triangle inequality).
    assert listed.error == pytest.approx(1.0, abs=listed.threshold)
    world = to_site(np.asarray(fragment["keypoints_local"]), np.asarray(fragment["pose"]))
    np.testing.assert_allclose(listed.truth, world[:, :2], atol=1e-9)
    assert np.linalg.norm(listed.estimate - listed.truth, axis=1) == pytest.approx(1.0, abs=0.1)
    assert describe(listed).startswith(f"1000 {fragment['id']}: error {listed.error:.2f} m")
    assert main(["--scenes", "1", "--seed", "1000"]) == 0
    assert "frames wrong in plan" in capsys.readouterr().out
