"""The zenoh transport shared by the service's front end (:mod:`api.zenoh`) and robots
(:mod:`robot`): the key expressions (:mod:`transport.keys`) and the one place a session's
configuration is built (:mod:`transport.config`).

Apart from both so that a robot runs none of the server and the server none of the robot.
"""
