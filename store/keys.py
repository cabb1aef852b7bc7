"""Every Redis key and channel name of the service, in one place.

Layout (``P`` is the configured prefix, ``S`` a site id, ``F`` a fragment id; ids match
:data:`schemas.ids.ID_PATTERN`, so they never contain the ``:`` separator):

========================  ======  =======================================================
key                       type    holds
========================  ======  =======================================================
P:jobs                    stream  pending jobs (consumer group ``workers``)
P:jobs:dead               stream  dead letters (jobs given up on)
P:job:ID:tries            string  delivery counter of one job
P:workers                 zset    worker id -> last heartbeat (unix time)
P:stats                   hash    job counters and duration histograms
P:sites                   zset    site id -> creation time
P:site:S                  hash    site record: generation, placement state, result info
P:site:S:fragments        zset    fragment id -> upload time (the order of the result)
P:site:S:frag:F           hash    fragment record: sha256, size, state, stage, progress
P:site:S:frag:F:data      string  the uploaded file bytes, zlib-compressed
P:site:S:frag:F:layout    string  LocalLayoutWire JSON
P:site:S:result           string  ResultModel JSON of the newest placement
P:site:S:hints            string  HintsModel JSON (contract section 2), replaced as a whole
P:site:S:placement        string  id of the one queued/running placement job (with TTL)
P:site:S:events           pubsub  SiteEvent JSON (fragment, placement, result, site)
P:site:S:senders          hash    fragment id -> SenderRecord JSON (zenoh robot, ROS topic)
P:results                 pubsub  ``{"site_id", "generation", "result"}`` per placement
P:presence                zset    zenoh front end id -> last presence refresh (unix time)
P:presence:Z              hash    robot id -> connected since, as seen by front end Z (TTL)
P:rate:C:W                string  uploads of client C (hashed token or address) in window W
========================  ======  =======================================================

A site exists while its hash ``P:site:S`` does (created with its entry in ``P:sites``);
:meth:`Keys.site_keys` lists every key a site owns, for deleting it.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["GROUP", "Keys"]

GROUP = "workers"


@dataclass(frozen=True)
class Keys:
    """Key names under one prefix."""

    prefix: str = "fpj"

    @property
    def jobs(self) -> str:
        return f"{self.prefix}:jobs"

    @property
    def dead(self) -> str:
        return f"{self.prefix}:jobs:dead"

    def tries(self, job_id: str) -> str:
        return f"{self.prefix}:job:{job_id}:tries"

    @property
    def workers(self) -> str:
        return f"{self.prefix}:workers"

    @property
    def stats(self) -> str:
        return f"{self.prefix}:stats"

    @property
    def sites(self) -> str:
        return f"{self.prefix}:sites"

    def site(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}"

    def fragments(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:fragments"

    def fragment(self, site_id: str, fragment_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:frag:{fragment_id}"

    def fragment_data(self, site_id: str, fragment_id: str) -> str:
        return f"{self.fragment(site_id, fragment_id)}:data"

    def fragment_layout(self, site_id: str, fragment_id: str) -> str:
        return f"{self.fragment(site_id, fragment_id)}:layout"

    def result(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:result"

    def hints(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:hints"

    def placement_flag(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:placement"

    def site_channel(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:events"

    @property
    def results_channel(self) -> str:
        return f"{self.prefix}:results"

    def site_senders(self, site_id: str) -> str:
        return f"{self.prefix}:site:{site_id}:senders"

    def site_keys(self, site_id: str, fragment_ids: Iterable[str]) -> list[str]:
        """Every key the site owns, given its fragment ids (not its entry in ``P:sites``)."""
        names = [
            self.site(site_id),
            self.fragments(site_id),
            self.result(site_id),
            self.hints(site_id),
            self.placement_flag(site_id),
            self.site_senders(site_id),
        ]
        for fid in fragment_ids:
            names += [
                self.fragment(site_id, fid),
                self.fragment_data(site_id, fid),
                self.fragment_layout(site_id, fid),
            ]
        return names

    def upload_rate(self, client_id: str, window: int) -> str:
        return f"{self.prefix}:rate:{client_id}:{window}"

    @property
    def presence_fronts(self) -> str:
        return f"{self.prefix}:presence"

    def presence(self, front_id: str) -> str:
        return f"{self.prefix}:presence:{front_id}"
