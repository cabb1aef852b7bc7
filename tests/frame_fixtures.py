"""Shared RGB-D frame scenes for the tests: an empty rectangular room seen by a wide-angle
camera from one station in three frames (each frame's layout is reliable, and three close
the loop), Kinect views of a given room, and helpers to zip a frame as an upload."""

from __future__ import annotations

import io
import math
import zipfile
from functools import cache

import numpy as np
import open3d as o3d

from schemas.frames import IntrinsicsModel
from services.rgbd import RgbdFrame, encode_frame_files
from services.synthetic.furniture import Furnishing
from services.synthetic.render import (
    CAMERAS,
    KINECT,
    FrameScene,
    FrameSpec,
    camera_pose,
    generate_frame_scene,
    render_frame,
    scene_mesh,
)
from services.synthetic.room import Room

WIDE = CAMERAS["wide"]
THREE_FRAMES = FrameSpec(
    n_corners_range=(4, 4),
    size_range=((4.0, 4.5), (5.0, 5.5)),
    intrinsics=WIDE,
    furniture=False,
    openings=False,
    n_stations=(1, 1),
    pitch_deg=(-10.0, -5.0),
)
# Seeds 1-7 and 9 of THREE_FRAMES give the right room at about 0.88, 'ambiguous' with slid
# runners-up: the frames' calibration (services.confidence) found no frame room of the tune
# seeds sure enough to close, so a frame site closes only past 0.99997 by the clouds'.
# Seed 0's room is right too (0.75), with a runner-up of its own.
ROOM_SEED = 4


@cache
def three_frames(seed: int = 0) -> FrameScene:
    """A room and its three wide-angle frames (cached: rendering takes a second)."""
    return generate_frame_scene(THREE_FRAMES, seed)


def render_views(
    room: Room,
    furnishing: Furnishing,
    stances: dict[str, tuple[tuple[float, float, float], float, float]],
    camera: IntrinsicsModel = KINECT,
) -> dict[str, tuple[RgbdFrame, np.ndarray]]:
    """Noise-free frames of a room (Kinect unless ``camera``): name -> (frame, its (4, 4)
    optical -> world pose) for each stance name -> (camera position (x, y, z), yaw and
    pitch in degrees)."""
    vertices, triangles, material = scene_mesh(room, furnishing)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor.from_numpy(vertices), o3d.core.Tensor.from_numpy(triangles))
    out = {}
    for name, (position, yaw, pitch) in stances.items():
        pose = camera_pose(np.array(position), math.radians(yaw), math.radians(pitch), 0.0)
        render = render_frame(scene, material, pose, camera, 7.0)
        out[name] = (RgbdFrame(render.depth, camera, render.color), pose)
    return out


def frame_files(frame: RgbdFrame, color_format: str = "png") -> dict[str, bytes]:
    """The frame's files (depth.png, intrinsics.json, color.png or .jpg) as bytes."""
    return encode_frame_files(frame.depth, frame.intrinsics, frame.color, color_format)


def zip_files(files: dict[str, bytes], folder: str = "") -> bytes:
    """A zip archive of ``files`` (name -> bytes), optionally inside one folder."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in files.items():
            archive.writestr(f"{folder}{name}", data)
    return out.getvalue()


def frame_zip(frame: RgbdFrame) -> bytes:
    """A frame as the zip archive an upload carries."""
    return zip_files(frame_files(frame))


def raw_zip(entries: list[tuple[str, bytes]]) -> bytes:
    """A zip archive of ``entries`` (name, bytes) as given: names unchecked, duplicates kept."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries:
            archive.writestr(zipfile.ZipInfo(name), data, zipfile.ZIP_DEFLATED)
    return out.getvalue()


def zip_bomb(size: int) -> bytes:
    """A zip with one ``size``-byte entry of zeros (a few MB compressed)."""
    out = io.BytesIO()
    block = bytes(1 << 22)
    with (
        zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive,
        archive.open("depth.png", "w", force_zip64=True) as entry,
    ):
        for _ in range(size // len(block)):
            entry.write(block)
    return out.getvalue()
