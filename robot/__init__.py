"""The robot's side of the zenoh front end: ``jigsaw send`` and ``jigsaw watch``.

Apart from the server (``api``) so that a robot runs none of it: it shares only the zenoh
transport (key expressions and session configuration, :mod:`transport`) and the wire models in
:mod:`schemas`.
"""
