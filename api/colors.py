"""One stable colour per fragment id, the same in every picture and in the web view.

The colour depends on the id only (not on arrival order or on the other fragments): the
32-bit FNV-1a hash of the id's UTF-8 bytes, mixed by murmur3's finalizer so that ids differing
in one character get far-apart colours, picks the hue (hash mod 360) and one of two
lightnesses (bit 16), at 70 % saturation. ``api/web/static/common.js`` computes the same
colour with the same arithmetic (``fragmentColor``).
"""

from __future__ import annotations

__all__ = ["fnv1a32", "fragment_color", "fragment_rgb", "id_hash"]

_SATURATION = 0.7
_LIGHTNESS = (0.36, 0.46)


def fnv1a32(text: str) -> int:
    """32-bit FNV-1a hash of the UTF-8 bytes of ``text``.

    Examples
    --------
    >>> fnv1a32("")
    2166136261
    >>> fnv1a32("a")
    3826002220
    """
    value = 0x811C9DC5
    for byte in text.encode("utf-8"):
        value = ((value ^ byte) * 0x01000193) & 0xFFFFFFFF
    return value


def id_hash(text: str) -> int:
    """:func:`fnv1a32` mixed by murmur3's 32-bit finalizer (fmix32).

    Examples
    --------
    >>> id_hash("a") != id_hash("b")
    True
    """
    value = fnv1a32(text)
    value ^= value >> 16
    value = (value * 0x85EBCA6B) & 0xFFFFFFFF
    value ^= value >> 13
    value = (value * 0xC2B2AE35) & 0xFFFFFFFF
    value ^= value >> 16
    return value


def _channel(m1: float, m2: float, hue: float) -> float:
    """CSS Color 3 ``hue_to_rgb`` (hue in turns)."""
    hue = hue % 1.0
    if hue * 6 < 1:
        return m1 + (m2 - m1) * hue * 6
    if hue * 2 < 1:
        return m2
    if hue * 3 < 2:
        return m1 + (m2 - m1) * (2 / 3 - hue) * 6
    return m1


def fragment_rgb(fragment_id: str) -> tuple[int, int, int]:
    """The fragment's colour as 8-bit (r, g, b).

    Examples
    --------
    >>> fragment_rgb("frag_00") == fragment_rgb("frag_00")
    True
    """
    value = id_hash(fragment_id)
    hue = (value % 360) / 360
    lightness, saturation = _LIGHTNESS[(value >> 16) & 1], _SATURATION
    m2 = lightness * (saturation + 1)  # lightness <= 0.5
    m1 = lightness * 2 - m2
    r, g, b = (_channel(m1, m2, hue + shift) for shift in (1 / 3, 0.0, -1 / 3))
    return int(r * 255 + 0.5), int(g * 255 + 0.5), int(b * 255 + 0.5)


def fragment_color(fragment_id: str) -> str:
    """The fragment's colour as ``#rrggbb``.

    Examples
    --------
    >>> fragment_color("frag_00").startswith("#") and len(fragment_color("frag_00")) == 7
    True
    """
    return "#{:02x}{:02x}{:02x}".format(*fragment_rgb(fragment_id))
