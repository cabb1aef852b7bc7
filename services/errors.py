"""The project's exception hierarchy: one root, one subclass per failure kind.

Front ends map these to HTTP status codes and CLI exit codes in one place each.
"""

from __future__ import annotations

__all__ = [
    "ArchiveTooLargeError",
    "ColorSizeError",
    "EmptyDepthError",
    "FragmentError",
    "FragmentTooLargeError",
    "InvalidArchiveError",
    "InvalidDepthError",
    "InvalidFragmentError",
    "InvalidFrameError",
    "InvalidIntrinsicsError",
    "JigsawError",
    "MissingFrameFileError",
    "UnsupportedFormatError",
]


class JigsawError(Exception):
    """Root of every error the project raises on purpose.

    ``code`` is a stable, machine-readable identifier used on the wire.
    """

    code = "jigsaw_error"

    def __init__(self, message: str, *, code: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code


class FragmentError(JigsawError):
    """A fragment's bytes cannot be used."""

    code = "invalid_fragment"


class UnsupportedFormatError(FragmentError):
    """The bytes are neither PLY nor PCD."""

    code = "unsupported_format"


class InvalidFragmentError(FragmentError):
    """PLY/PCD, but the content is unusable (truncated, inconsistent, no x/y/z, too few points)."""

    code = "invalid_fragment"


class FragmentTooLargeError(FragmentError):
    """More points (or bytes) than the configured maximum."""

    code = "fragment_too_large"


class InvalidArchiveError(InvalidFragmentError):
    """A zip archive that is truncated, not a zip, or hostile (nested archives, ``..`` or
    absolute paths, unexpected members)."""

    code = "invalid_archive"


class ArchiveTooLargeError(FragmentTooLargeError):
    """A zip archive with too many entries, or entries (or a total) too large uncompressed."""

    code = "archive_too_large"


class InvalidFrameError(InvalidFragmentError):
    """An RGB-D frame (contract section 1) whose files cannot be used."""

    code = "invalid_frame"


class MissingFrameFileError(InvalidFrameError):
    """``depth.png`` or ``intrinsics.json`` is missing."""

    code = "missing_frame_file"


class InvalidDepthError(InvalidFrameError):
    """The depth image is not a 16-bit single-channel PNG (8-bit, RGB, corrupt)."""

    code = "invalid_depth"


class EmptyDepthError(InvalidFrameError):
    """The depth image holds no usable reading (all zero, or none in the depth range)."""

    code = "empty_depth"


class InvalidIntrinsicsError(InvalidFrameError):
    """``intrinsics.json`` is not valid, or does not match the depth image's size."""

    code = "invalid_intrinsics"


class ColorSizeError(InvalidFrameError):
    """The colour image is not the depth image's size (or cannot be decoded)."""

    code = "invalid_color"
