"""The one decoder of upload bytes: RGB-D frame archives read (a frame or a frame folder) and
checked (hostile names, truncation, entry count and sizes, lying size headers, expansion
ratio)."""

from __future__ import annotations

import pytest

from schemas.frames import ArchiveLimits
from services.errors import ArchiveTooLargeError, InvalidArchiveError
from services.rgbd import RgbdFrame
from services.uploads import decode_upload, read_frame_archive
from tests.frame_fixtures import frame_files, raw_zip, three_frames, zip_bomb, zip_files

pytestmark = pytest.mark.timeout(120)


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
        read_frame_archive(raw_zip(entries))


def test_truncated_archive_is_invalid(files) -> None:
    data = zip_files(files)
    with pytest.raises(InvalidArchiveError) as caught:
        decode_upload(data[: len(data) // 2])
    assert caught.value.code == "invalid_archive"


def test_entry_count_and_sizes_are_capped(files) -> None:
    many = raw_zip([(f"f{k}.txt", b"x") for k in range(20)])
    with pytest.raises(ArchiveTooLargeError):
        read_frame_archive(many)
    small = ArchiveLimits(max_entry_bytes=1000, max_total_bytes=10_000)
    with pytest.raises(ArchiveTooLargeError):
        read_frame_archive(zip_files(files), small)


def test_a_lying_size_header_cannot_inflate_past_the_cap() -> None:
    data = bytearray(raw_zip([("depth.png", bytes(200_000))]))
    # Declare 100 bytes uncompressed in the central directory (and the local header).
    central = data.rfind(b"PK\x01\x02")
    data[central + 24 : central + 28] = (100).to_bytes(4, "little")
    data[22:26] = (100).to_bytes(4, "little")
    with pytest.raises((InvalidArchiveError, ArchiveTooLargeError)):
        read_frame_archive(bytes(data), ArchiveLimits(max_entry_bytes=1000))


def test_an_archive_may_not_inflate_far_past_its_own_size(files) -> None:
    """32 MiB of zeros fit in the byte caps but deflate to ~32 KiB: a thousandfold bomb."""
    bomb = zip_bomb(32 << 20)
    assert len(bomb) * 100 < 32 << 20 <= ArchiveLimits().max_total_bytes
    with pytest.raises(ArchiveTooLargeError, match="times its size"):
        read_frame_archive(bomb)
    assert read_frame_archive(bomb, ArchiveLimits(max_ratio=10_000))["depth.png"] == bytes(32 << 20)
    # A real frame (PNGs barely shrink) is far from the ratio; tiny archives pass whatever it.
    frame = zip_files(files)
    assert read_frame_archive(frame, ArchiveLimits(max_ratio=1.5))
    tiny = raw_zip([("depth.png", bytes(500_000))])
    assert read_frame_archive(tiny, ArchiveLimits(max_ratio=1)) == {"depth.png": bytes(500_000)}
