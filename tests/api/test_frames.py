"""RGB-D frames over HTTP: zip archives checked (hostile, truncated, too large), bad frames
refused with their code and nothing stored, and three frames that close a room end to end
(real uvicorn, real workers, Redis)."""

from __future__ import annotations

import io
import zipfile

import pytest

from schemas.frames import ArchiveLimits
from services.errors import ArchiveTooLargeError, InvalidArchiveError
from services.rgbd import RgbdFrame
from services.uploads import decode_upload, read_frame_archive
from tests.frame_fixtures import frame_files, frame_zip, three_frames, zip_files
from tests.service_fixtures import ApiServer, redis_snapshot, wait_result

pytestmark = pytest.mark.timeout(120)


def _raw_zip(entries: list[tuple[str, bytes]]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in entries:
            archive.writestr(zipfile.ZipInfo(name), data, zipfile.ZIP_DEFLATED)
    return out.getvalue()


def _bomb(size: int) -> bytes:
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


@pytest.fixture(scope="module")
def files() -> dict[str, bytes]:
    return frame_files(three_frames(0).frames[0].frame)


def test_a_zipped_frame_and_a_zipped_frame_folder_decode(files) -> None:
    assert isinstance(decode_upload(zip_files(files)), RgbdFrame)
    assert isinstance(decode_upload(zip_files(files, folder="frame_01/")), RgbdFrame)
    extra = zip_files({**files, "notes.txt": b"ignored"})
    assert read_frame_archive(extra).keys() == files.keys()


@pytest.mark.parametrize(
    "entries",
    [
        [("../depth.png", b"x")],
        [("/etc/depth.png", b"x")],
        [("a\\depth.png", b"x")],
        [("a/b/depth.png", b"x")],
        [("inner.zip", b"x")],
        [("depth.png", b"PK\x03\x04 nested")],
        [("a/depth.png", b"x"), ("b/intrinsics.json", b"{}")],
        [("depth.png", b"x"), ("DEPTH.PNG", b"y")],
    ],
)
def test_hostile_archives_are_refused(entries) -> None:
    with pytest.raises(InvalidArchiveError):
        read_frame_archive(_raw_zip(entries))


def test_truncated_archive_is_invalid(files) -> None:
    data = zip_files(files)
    with pytest.raises(InvalidArchiveError) as caught:
        decode_upload(data[: len(data) // 2])
    assert caught.value.code == "invalid_archive"


def test_entry_count_and_sizes_are_capped(files) -> None:
    many = _raw_zip([(f"f{k}.txt", b"x") for k in range(20)])
    with pytest.raises(ArchiveTooLargeError):
        read_frame_archive(many)
    small = ArchiveLimits(max_entry_bytes=1000, max_total_bytes=10_000)
    with pytest.raises(ArchiveTooLargeError):
        read_frame_archive(zip_files(files), small)


def test_a_lying_size_header_cannot_inflate_past_the_cap() -> None:
    data = bytearray(_raw_zip([("depth.png", bytes(200_000))]))
    # Declare 100 bytes uncompressed in the central directory (and the local header).
    central = data.rfind(b"PK\x01\x02")
    data[central + 24 : central + 28] = (100).to_bytes(4, "little")
    data[22:26] = (100).to_bytes(4, "little")
    with pytest.raises((InvalidArchiveError, ArchiveTooLargeError)):
        read_frame_archive(bytes(data), ArchiveLimits(max_entry_bytes=1000))


def test_an_archive_may_not_inflate_far_past_its_own_size(files) -> None:
    """32 MiB of zeros fit in the byte caps but deflate to ~32 KiB: a thousandfold bomb."""
    bomb = _bomb(32 << 20)
    assert len(bomb) * 100 < 32 << 20 <= ArchiveLimits().max_total_bytes
    with pytest.raises(ArchiveTooLargeError, match="times its size"):
        read_frame_archive(bomb)
    assert read_frame_archive(bomb, ArchiveLimits(max_ratio=10_000))["depth.png"] == bytes(32 << 20)
    # A real frame (PNGs barely shrink) is far from the ratio; tiny archives pass whatever it.
    frame = zip_files(files)
    assert read_frame_archive(frame, ArchiveLimits(max_ratio=1.5))
    tiny = _raw_zip([("depth.png", bytes(500_000))])
    assert read_frame_archive(tiny, ArchiveLimits(max_ratio=1)) == {"depth.png": bytes(500_000)}


def test_a_gigabyte_entry_over_http_is_413_and_nothing_is_stored(
    server: ApiServer, redis_client
) -> None:
    bomb = _bomb(1 << 30)
    assert len(bomb) < 8_000_000  # 1 GiB inflated
    before = redis_snapshot(redis_client)
    with server.client() as http:
        reply = http.put("/v1/sites/s/fragments/f", content=bomb)
    assert reply.status_code == 413
    assert reply.json()["error"]["code"] == "archive_too_large"
    assert redis_snapshot(redis_client) == before


def test_bad_frames_over_http_get_their_code_and_store_nothing(
    server: ApiServer, redis_client, files
) -> None:
    flat = dict(files, **{"color.png": files["color.png"][:100]})
    cases = [
        (zip_files({"depth.png": files["depth.png"]}), 422, "missing_frame_file"),
        (zip_files(flat), 422, "invalid_color"),
        (b"PK\x03\x04truncated", 422, "invalid_archive"),
        (_raw_zip([("../x", b"1")]), 422, "invalid_archive"),
        (b"GIF89a", 415, "unsupported_format"),
    ]
    before = redis_snapshot(redis_client)
    with server.client() as http:
        for body, status, code in cases:
            reply = http.put("/v1/sites/s/fragments/f", content=body)
            assert (reply.status_code, reply.json()["error"]["code"]) == (status, code)
    assert redis_snapshot(redis_client) == before


def test_three_zipped_frames_close_the_site(server: ApiServer) -> None:
    scene = three_frames(0)
    with server.client() as http:
        for f in scene.frames:
            reply = http.put(
                f"/v1/sites/rgbd/fragments/{f.id}",
                content=frame_zip(f.frame),
                headers={"content-type": "application/zip"},
            )
            assert reply.status_code == 202, reply.text
            assert reply.json()["format"] == "rgbd"
        result = wait_result(http, "rgbd", timeout=90, status="closed")
    assert all(f["placed"] for f in result["fragments"])
    assert len(result["floorplan"]["rooms"]) == 1
