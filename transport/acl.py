"""zenoh's own access control (``access_control`` of the session config) from the peers'
scopes (``FPJ_ZENOH_ACL``): which peer may send fragments of which site, and receive which
site's results and poses.

zenoh knows a peer by what authenticated it when its session opened: the common name of its
client certificate (mutual TLS) or its user name (``transport/auth/usrpwd``). Everything not
allowed here is denied, so a peer zenoh cannot name (no certificate, unknown user) or that
has no scope may neither put nor query fragments, nor subscribe to or query results and
poses. Rules filter each message between the service and one peer, seen from the service:
``ingress`` what the peer sends, ``egress`` what the service sends it.

- every known peer: the service's declarations (its fragment and result queryables and its
  fragment subscriber are declared on wildcard keys, and a rule allows a message only on keys
  it includes), the service info queryable and robot presence (liveliness);
- ``upload`` on a site: put and query its fragment keys, get the replies;
- ``read`` on a site: subscribe to and query its result and poses, get them.

``delete`` has no zenoh message: only HTTP deletes.

ROS 2 topics (rmw_zenoh keys ``<domain>/<topic>/<type>/<hash>``, :class:`RosTopics`) follow
the same rights: ``upload`` on a site lets a peer publish on the cloud and depth topics of
that site; ``read`` on every site (``*``) lets it subscribe to the pose, transform and map
topics, which carry every site's results; every known peer takes part in the ROS graph
(liveliness tokens ``@ros2_lv/<domain>/**``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from schemas.access import Scope
from transport.keys import ZenohKeys

__all__ = ["RosTopics", "access_control"]


@dataclass(frozen=True)
class RosTopics:
    """The ROS 2 topics the service subscribes to (topic -> site) and publishes on."""

    domain_id: int = 0
    inputs: Mapping[str, str] = field(default_factory=dict)
    outputs: tuple[str, ...] = ()

    def key(self, topic: str) -> str:
        """Every type and type hash of ``topic``."""
        return f"{self.domain_id}/{topic.strip('/')}/*/*"

    def input_keys(self, scope: Scope) -> list[str]:
        """The input topics of the scope's sites."""
        return [self.key(t) for t, site in self.inputs.items() if scope.covers(site)]


def _rule(rule_id: str, messages: list[str], flow: str, keys: Iterable[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "messages": messages,
        "flows": [flow],
        "permission": "allow",
        "key_exprs": sorted(set(keys)),
    }


def _site_rules(
    keys: ZenohKeys, ros: RosTopics | None, name: str, scope: Scope
) -> list[dict[str, Any]]:
    sites = ["*"] if scope.all_sites else list(scope.sites)
    rules = []
    if "upload" in scope.rights:
        fragments = [keys.fragment(site, "*") for site in sites]
        rules += [
            _rule(f"{name}/upload/in", ["put", "query"], "ingress", fragments),
            _rule(f"{name}/upload/out", ["reply"], "egress", fragments),
        ]
        if ros is not None and ros.input_keys(scope):
            rules.append(_rule(f"{name}/upload/ros", ["put"], "ingress", ros.input_keys(scope)))
    if "read" in scope.rights:
        results = [k for site in sites for k in (keys.result(site), keys.site_poses(site))]
        rules += [
            _rule(f"{name}/read/in", ["declare_subscriber", "query"], "ingress", results),
            _rule(f"{name}/read/out", ["put", "reply"], "egress", results),
        ]
        if ros is not None and ros.outputs and scope.all_sites:
            outputs = [ros.key(topic) for topic in ros.outputs]
            rules += [
                _rule(f"{name}/read/ros/in", ["declare_subscriber"], "ingress", outputs),
                _rule(f"{name}/read/ros/out", ["put"], "egress", outputs),
            ]
    return rules


def _common_rules(keys: ZenohKeys, ros: RosTopics | None) -> list[dict[str, Any]]:
    declared = [keys.all_fragments, keys.all_results]
    declarations = ["declare_queryable", "declare_subscriber"]
    presence = ["liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
    rules = [
        _rule("known/declarations", declarations, "egress", declared),
        _rule("known/service/in", ["query"], "ingress", [keys.service]),
        _rule("known/service/out", ["declare_queryable", "reply"], "egress", [keys.service]),
        _rule("known/presence/in", presence, "ingress", [keys.all_robots]),
        _rule("known/presence/out", presence, "egress", [keys.all_robots]),
    ]
    if ros is not None:
        graph = [f"@ros2_lv/{ros.domain_id}/**"]
        inputs = [ros.key(topic) for topic in ros.inputs]
        rules += [
            _rule("known/ros/graph/in", presence, "ingress", graph),
            _rule("known/ros/graph/out", presence, "egress", graph),
        ]
        if inputs:
            rules.append(_rule("known/ros/declarations", ["declare_subscriber"], "egress", inputs))
    return rules


def access_control(
    keys: ZenohKeys,
    peers: Mapping[str, Scope],
    *,
    by_certificate: bool,
    by_user: bool,
    ros: RosTopics | None = None,
) -> dict[str, Any]:
    """The ``access_control`` section for ``peers`` (name -> scope), each known by its
    certificate's common name (``by_certificate``), its user name (``by_user``) or either;
    ``ros``: the ROS 2 topics of the service, if it joins the ROS graph.

    >>> acl = access_control(
    ...     ZenohKeys(), {"r1": Scope(sites=("lab",), rights=("upload",))},
    ...     by_certificate=True, by_user=False)
    >>> acl["subjects"]
    [{'id': 'r1/cn', 'cert_common_names': ['r1']}]
    >>> [r["key_exprs"] for r in acl["rules"] if r["id"] == "r1/upload/in"]
    [['fpj/sites/lab/fragments/*']]
    """
    if not (by_certificate or by_user):
        raise ValueError("access control needs peers named by certificate or by user")
    rules, subjects, policies = _common_rules(keys, ros), [], []
    common = [rule["id"] for rule in rules]
    for name, scope in peers.items():
        own = _site_rules(keys, ros, name, scope)
        rules += own
        named = []
        if by_certificate:
            named.append({"id": f"{name}/cn", "cert_common_names": [name]})
        if by_user:
            named.append({"id": f"{name}/user", "usernames": [name]})
        subjects += named
        policies.append(
            {"rules": common + [r["id"] for r in own], "subjects": [s["id"] for s in named]}
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
