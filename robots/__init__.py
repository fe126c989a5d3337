"""Robot files of manip_id: our own models and per-robot identification profiles.

This folder sits at the top of the source tree and is installed as the package
``manip_id.robots`` (pyproject maps one to the other): ``msd.urdf`` and
``msd.json`` (the one-DoF mass-spring-damper and its settings) and one TOML
profile per robot (``panda.toml``, ``msd.toml``, ...) read by
:func:`manip_id.robot.profiles.load_profile`.
"""
