"""The robot's side of the zenoh front end: ``jigsaw send`` and ``jigsaw watch``.

Apart from the server (``api``) so that a robot runs none of it: it shares only the service's
zenoh key expressions and session configuration (:mod:`api.zenoh.keys`,
:mod:`api.zenoh.config`) and the wire models in :mod:`schemas`.
"""
