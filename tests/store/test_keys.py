"""Redis key names: one prefix, and every key a site owns listed for its deletion."""

from __future__ import annotations

import pytest

from store.keys import Keys

pytestmark = pytest.mark.timeout(10)


def test_a_sites_keys_are_every_key_named_after_it() -> None:
    keys = Keys("p")
    owned = set(keys.site_keys("s", ["f1", "f2"]))
    per_site = {
        keys.site("s"),
        keys.fragments("s"),
        keys.result("s"),
        keys.hints("s"),
        keys.placement_flag("s"),
        keys.site_senders("s"),
    }
    per_fragment = {
        name
        for fid in ("f1", "f2")
        for name in (
            keys.fragment("s", fid),
            keys.fragment_data("s", fid),
            keys.fragment_layout("s", fid),
        )
    }
    assert owned == per_site | per_fragment
    assert all(name.startswith("p:site:s") for name in owned)
    assert keys.site_channel("s") not in owned  # a pub/sub channel holds no data
    assert not any(name.startswith("p:site:s:") for name in Keys("p").site_keys("t", ["f1"]))


def test_keys_are_namespaced() -> None:
    keys = Keys("pfx")
    names = [
        keys.jobs,
        keys.dead,
        keys.workers,
        keys.sites,
        keys.site("s"),
        keys.fragment("s", "f"),
        keys.fragment_data("s", "f"),
        keys.result("s"),
        keys.placement_flag("s"),
    ]
    assert all(name.startswith("pfx:") for name in names)
    assert len(set(names)) == len(names)
