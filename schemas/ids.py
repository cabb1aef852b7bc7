"""The one pattern of site, fragment and robot ids (contract section 4)."""

from __future__ import annotations

import re

__all__ = ["ID_PATTERN", "ID_REGEX", "ID_RULE", "is_valid_id"]

# 1 to 64 characters of [A-Za-z0-9._-], but not "." or ".." (they name no file or key).
ID_PATTERN = r"^(?!\.{1,2}$)[A-Za-z0-9._-]{1,64}$"
ID_REGEX = re.compile(ID_PATTERN)
ID_RULE = "1 to 64 characters of [A-Za-z0-9._-], not . or .."  # the pattern, for people


def is_valid_id(value: str) -> bool:
    r"""True for a usable id.

    >>> [is_valid_id(v) for v in ("frag_00", "a.b-c", "..", ".", "", "a/b", "a\n")]
    [True, True, False, False, False, False, False]
    """
    return ID_REGEX.fullmatch(value) is not None  # match() would let "$" pass a final newline
