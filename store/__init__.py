"""The service's shared data layer: everything the API and the workers both read or write.

Redis connections (:mod:`store.connection`), every key name (:mod:`store.keys`), the hash
records and their wire status (:mod:`store.records`), job enqueue, placement coalescing and
acknowledgements (:mod:`store.jobs`), dead letters (:mod:`store.dead_letters`), job statistics
(:mod:`store.stats`), robot presence and senders (:mod:`store.presence`), the local layout's
stored form (:mod:`store.layouts`), what a front end holds to reach it all
(:mod:`store.backend`), and the one log format of every process (:mod:`store.logs`).

``api`` and ``worker`` both build on this package; neither imports the other.
"""
