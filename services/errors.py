"""The project's exception hierarchy: one root, one subclass per failure kind.

Front ends map these to HTTP status codes and CLI exit codes in one place each.
"""

from __future__ import annotations

__all__ = [
    "FragmentError",
    "FragmentTooLargeError",
    "InvalidFragmentError",
    "JigsawError",
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
