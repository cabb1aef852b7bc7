"""Every zenoh key expression of the service, in one place (contract section 5).

======================================  ==========  ===========================================
key expression (prefix ``P``)           kind        payload
======================================  ==========  ===========================================
P/sites/{site}/fragments/{fragment}     queryable   query: the file bytes; reply: UploadReply or
                                                    the error body (as a zenoh error reply)
P/sites/{site}/fragments/{fragment}     subscriber  put: the file bytes (no acknowledgement)
P/sites/{site}/result                   publisher   the result JSON, after each placement
P/sites/{site}/result                   queryable   the latest result JSON (late joiners)
P/sites/{site}/poses/{fragment}         publisher   PoseUpdate JSON, after each placement
P/robots/{robot}                        liveliness  declared by robots; the service tracks them
P/service                               queryable   ServiceInfo JSON (limits)
======================================  ==========  ===========================================
"""

from __future__ import annotations

from dataclasses import dataclass

from schemas.ids import is_valid_id

__all__ = ["ZenohKeys"]


@dataclass(frozen=True)
class ZenohKeys:
    """Key expressions under one prefix (``fpj`` by default)."""

    prefix: str = "fpj"

    def fragment(self, site_id: str, fragment_id: str) -> str:
        return f"{self.prefix}/sites/{site_id}/fragments/{fragment_id}"

    @property
    def all_fragments(self) -> str:
        return f"{self.prefix}/sites/*/fragments/*"

    def result(self, site_id: str) -> str:
        return f"{self.prefix}/sites/{site_id}/result"

    @property
    def all_results(self) -> str:
        return f"{self.prefix}/sites/*/result"

    def pose(self, site_id: str, fragment_id: str) -> str:
        return f"{self.prefix}/sites/{site_id}/poses/{fragment_id}"

    def site_poses(self, site_id: str) -> str:
        return f"{self.prefix}/sites/{site_id}/poses/*"

    def robot(self, robot_id: str) -> str:
        return f"{self.prefix}/robots/{robot_id}"

    @property
    def all_robots(self) -> str:
        return f"{self.prefix}/robots/*"

    @property
    def service(self) -> str:
        return f"{self.prefix}/service"

    def _chunks(self, key: str) -> list[str] | None:
        head = self.prefix + "/"
        return key[len(head) :].split("/") if key.startswith(head) else None

    def parse_fragment(self, key: str) -> tuple[str, str] | None:
        """``(site_id, fragment_id)`` of a fragment key, else None (ids are not checked here:
        a wildcard chunk comes back as it is, and the ingest refuses it as an invalid id).

        >>> ZenohKeys().parse_fragment("fpj/sites/lab/fragments/f1")
        ('lab', 'f1')
        >>> ZenohKeys().parse_fragment("fpj/sites/lab/result") is None
        True
        """
        chunks = self._chunks(key)
        if chunks is None or len(chunks) != 4 or chunks[0] != "sites" or chunks[2] != "fragments":
            return None
        return chunks[1], chunks[3]

    def parse_result(self, key: str) -> str | None:
        """The site id of a result key (may be a wildcard chunk such as ``*``), else None."""
        chunks = self._chunks(key)
        if chunks is None or len(chunks) != 3 or chunks[0] != "sites" or chunks[2] != "result":
            return None
        return chunks[1]

    def parse_robot(self, key: str) -> str | None:
        """The robot id of a liveliness token key, if it is a valid id."""
        chunks = self._chunks(key)
        if chunks is None or len(chunks) != 2 or chunks[0] != "robots":
            return None
        return chunks[1] if is_valid_id(chunks[1]) else None
