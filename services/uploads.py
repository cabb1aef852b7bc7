"""Uploads that are RGB-D frames: one zip archive of the frame's files (contract section 1).

The archive is untrusted: it is refused when truncated or not a zip, when it nests archives
or folders, names a path with ``..`` or an absolute path, repeats a name, or uses a
compression other than stored/deflate; and when it has too many entries, entries too large
uncompressed, or would inflate to many times its own size (a zip bomb). Sizes are checked on
the declared values first and again while inflating (a lying header cannot inflate past the
cap). :func:`decode_upload` is the one decoder of upload bytes for every front end (HTTP,
zenoh, workers, CLI).
"""

from __future__ import annotations

import io
import zipfile
import zlib
from pathlib import PurePosixPath

from schemas.frames import ArchiveLimits
from schemas.params import PipelineParams
from services.errors import ArchiveTooLargeError, InvalidArchiveError, UnsupportedFormatError
from services.fragments import Fragment
from services.parsing import parse_fragment
from services.rgbd import COLOR_NAMES, DEPTH_NAME, INTRINSICS_NAME, RgbdFrame, decode_frame

__all__ = ["FRAME_FILES", "decode_upload", "is_archive", "read_frame_archive"]

FRAME_FILES = (DEPTH_NAME, INTRINSICS_NAME, *COLOR_NAMES)
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
_CHUNK = 1 << 16
_METHODS = (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED)
_LIMITS = ArchiveLimits()


def is_archive(data: bytes) -> bool:
    """True when ``data`` starts like a zip archive (a local header or an empty archive)."""
    return data.startswith(_ZIP_MAGIC)


def _member_name(info: zipfile.ZipInfo) -> str | None:
    """The frame file an entry holds (None for a folder entry), or InvalidArchiveError."""
    raw = info.filename
    if "\\" in raw or raw.startswith("/") or (len(raw) > 1 and raw[1] == ":"):
        raise InvalidArchiveError(f"archive entry {raw[:80]!r}: absolute or Windows path")
    parts = PurePosixPath(raw).parts
    if any(part in ("..", ".") for part in parts):
        raise InvalidArchiveError(f"archive entry {raw[:80]!r}: '..' or '.' in the path")
    if info.is_dir():
        if len(parts) > 1:
            raise InvalidArchiveError(f"archive entry {raw[:80]!r}: nested folders")
        return None
    if len(parts) > 2:
        raise InvalidArchiveError(f"archive entry {raw[:80]!r}: nested folders")
    name = parts[-1]
    if name.lower().endswith((".zip", ".tar", ".gz", ".7z", ".rar")):
        raise InvalidArchiveError(f"archive entry {raw[:80]!r}: nested archive")
    return name


def _inflate(archive: zipfile.ZipFile, info: zipfile.ZipInfo, cap: int) -> bytes:
    """An entry's bytes, never more than ``cap`` of them (whatever its header says)."""
    out = bytearray()
    with archive.open(info) as stream:
        while chunk := stream.read(_CHUNK):
            out += chunk
            if len(out) > cap:
                raise ArchiveTooLargeError(
                    f"archive entry {info.filename[:80]!r} inflates past {cap} bytes"
                )
    return bytes(out)


def read_frame_archive(data: bytes, limits: ArchiveLimits = _LIMITS) -> dict[str, bytes]:
    """The frame files of a zip archive: name -> bytes.

    Files may sit at the root or in one folder (a zipped frame folder); other files are
    ignored. Raises InvalidArchiveError (truncated, hostile, nested) or ArchiveTooLargeError.
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, ValueError) as exc:
        raise InvalidArchiveError(f"not a readable zip archive (truncated?): {exc}") from exc
    with archive:
        infos = archive.infolist()
        if len(infos) > limits.max_entries:
            raise ArchiveTooLargeError(
                f"archive has {len(infos)} entries, more than {limits.max_entries}"
            )
        # The budget also bounds the expansion ratio: a few kilobytes may not become 128 MiB.
        budget = limits.budget(len(data))
        declared = sum(info.file_size for info in infos)
        if declared > budget:
            raise ArchiveTooLargeError(
                f"archive of {len(data)} bytes declares {declared} bytes uncompressed, more "
                f"than {budget} (at most {limits.max_total_bytes}, and {limits.max_ratio:g} "
                f"times its size above {limits.ratio_floor})"
            )
        return _members(archive, infos, limits, budget)


def _members(
    archive: zipfile.ZipFile, infos: list[zipfile.ZipInfo], limits: ArchiveLimits, budget: int
) -> dict[str, bytes]:
    files: dict[str, bytes] = {}
    folders = set()
    total = 0
    for info in infos:
        name = _member_name(info)
        if name is None:
            continue
        folders.add(PurePosixPath(info.filename).parts[:-1])
        if info.file_size > limits.max_entry_bytes:
            raise ArchiveTooLargeError(
                f"archive entry {info.filename[:80]!r} declares {info.file_size} bytes, "
                f"more than {limits.max_entry_bytes}"
            )
        if info.compress_type not in _METHODS:
            raise InvalidArchiveError(f"archive entry {info.filename[:80]!r}: unsupported method")
        if name.lower() in files:
            raise InvalidArchiveError(f"archive holds {name!r} twice")
        cap = min(limits.max_entry_bytes, budget - total)
        try:
            content = _inflate(archive, info, cap)
        except (
            zipfile.BadZipFile,
            zlib.error,
            EOFError,
            OSError,
            ValueError,
            NotImplementedError,
        ) as exc:
            raise InvalidArchiveError(f"archive entry {info.filename[:80]!r}: {exc}") from exc
        total += len(content)
        if content.startswith(_ZIP_MAGIC):
            raise InvalidArchiveError(f"archive entry {info.filename[:80]!r}: nested archive")
        if name.lower() in FRAME_FILES:
            files[name.lower()] = content
    if len(folders) > 1:
        raise InvalidArchiveError("archive files are spread over several folders")
    return files


def decode_upload(
    data: bytes,
    params: PipelineParams = PipelineParams(),
    limits: ArchiveLimits = _LIMITS,
) -> Fragment:
    """Decode an upload: a PLY or PCD file, or an RGB-D frame's zip archive.

    Raises
    ------
    UnsupportedFormatError
        Empty, or none of PLY, PCD, zip.
    FragmentError
        Any subclass: what is wrong with the cloud, the archive or the frame.
    """
    if is_archive(data):
        files = read_frame_archive(data, limits)
        frame: RgbdFrame = decode_frame(files, params.layout.frame, params.parser)
        return frame
    try:
        return parse_fragment(data, params.parser)
    except UnsupportedFormatError as exc:
        raise UnsupportedFormatError(
            exc.message.replace("not PLY or PCD", "not PLY, PCD or an RGB-D frame zip")
        ) from exc
