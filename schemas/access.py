"""Who may do what: the scope of a bearer token (``FPJ_TOKENS``) or of a zenoh peer
(``FPJ_ZENOH_ACL``): the sites it covers and the rights it has on them.

Three rights, one per kind of request, alike over HTTP and zenoh:

- ``read``: results, status, floorplans, hints, events, metrics; zenoh results and poses;
- ``upload``: fragments and hints (HTTP PUT, zenoh queries and puts on fragment keys);
- ``delete``: removing a fragment or a site.

A scope is written ``NAME``, ``NAME:SITES`` or ``NAME:SITES:RIGHTS``, with SITES and RIGHTS
``+``-separated or ``*`` (every site, every right), missing parts meaning ``*``: a bare name
keeps the meaning tokens always had, every right on every site.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import Annotated, Literal, get_args

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from schemas.ids import ID_RULE, is_valid_id

__all__ = ["ALL", "FULL", "RIGHTS", "Right", "Scope", "parse_scope", "parse_scopes"]

Right = Literal["read", "upload", "delete"]
RIGHTS: tuple[Right, ...] = get_args(Right)
ALL = "*"


def _site_pattern(value: str) -> str:
    if value != ALL and not is_valid_id(value):
        raise ValueError(f"expected a site id ({ID_RULE}) or {ALL}, got {value!r}")
    return value


class Scope(BaseModel):
    """Sites (``*``: all, present and future) and rights of one token or peer."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    sites: tuple[Annotated[str, AfterValidator(_site_pattern)], ...] = Field(
        (ALL,), min_length=1, description=f"site ids, or {ALL} for every site"
    )
    rights: tuple[Right, ...] = Field(RIGHTS, min_length=1, description="rights on those sites")

    @property
    def all_sites(self) -> bool:
        """True when the scope names every site (``*``)."""
        return ALL in self.sites

    def covers(self, site_id: str) -> bool:
        """True when the scope's sites include ``site_id``."""
        return self.all_sites or site_id in self.sites

    def allows(self, right: Right, site_id: str | None = None) -> bool:
        """``right`` on ``site_id``; ``None``: on every site (site-less routes such as metrics).

        >>> Scope(sites=("lab",), rights=("read",)).allows("read", "lab")
        True
        >>> Scope(sites=("lab",), rights=("read",)).allows("upload", "lab")
        False
        >>> Scope(sites=("lab",)).allows("read")
        False
        """
        if right not in self.rights:
            return False
        return self.all_sites if site_id is None else self.covers(site_id)


FULL = Scope()


def _split(part: str) -> tuple[str, ...]:
    return tuple(p.strip() for p in part.split("+") if p.strip()) if part.strip() != ALL else ()


def parse_scope(entry: str) -> tuple[str, Scope]:
    """``NAME[:SITES[:RIGHTS]]`` -> (name, scope).

    >>> parse_scope("robot1:lab+hall:upload+read")
    ('robot1', Scope(sites=('lab', 'hall'), rights=('upload', 'read')))
    >>> parse_scope("admin")[1] == Scope()
    True
    """
    name, _, rest = entry.strip().partition(":")
    sites, _, rights = rest.partition(":")
    fields: dict[str, tuple[str, ...]] = {}
    if _split(sites):
        fields["sites"] = _split(sites)
    if _split(rights):
        fields["rights"] = _split(rights)
    if not name.strip():
        raise ValueError(f"empty name in {entry!r}")
    return name.strip(), Scope.model_validate(fields)


def _entries(items: Iterable[object]) -> dict[str, Scope]:
    scopes: dict[str, Scope] = {}
    for item in items:
        if not isinstance(item, str):
            raise ValueError(f"expected NAME[:SITES[:RIGHTS]] strings, got {item!r}")
        if item.strip():
            name, scope = parse_scope(item)
            scopes[name] = scope
    return scopes


def parse_scopes(value: object) -> object:
    """The settings' forms of a scope table, as ``{name: Scope}`` (validated by pydantic).

    Accepted: ``"a,b:lab:read"`` (comma-separated entries), a JSON list of entries, a JSON
    object ``{"name": {"sites": [...], "rights": [...]}}`` (any character in names), or the
    same as Python lists and dicts.

    >>> sorted(parse_scopes("a, b:lab:read"))
    ['a', 'b']
    >>> parse_scopes('{"t": {"rights": ["read"]}}')
    {'t': {'rights': ['read']}}
    """
    if isinstance(value, str):
        text = value.strip()
        if text.startswith(("[", "{")):
            return parse_scopes(json.loads(text))
        return _entries(text.split(","))
    if isinstance(value, (list, tuple)):
        return _entries(value)
    return value
