"""Device interfaces (one module per kind of device) and their drivers.

- :mod:`hardware.device`  ``Device`` base, ``DeviceIdentity``, the ``Clock`` protocol, ``WallClock``
- :mod:`hardware.errors`  typed errors (``DeviceError`` and subclasses, ``ConfigError``)
- :mod:`hardware.arm`     ``Arm`` (UR10-like, ur_rtde units), ``ArmState``, ``Workspace``
- :mod:`hardware.hand`    ``Hand`` (Shadow Hand), ``JOINT_NAMES``, ``HandState``
- :mod:`hardware.biotac`  ``TactileSensors`` (BioTac SP), ``BiotacFrame``, ``FINGERS``
- :mod:`hardware.pour`    ``Pump``, ``Scale`` and their samples
- :mod:`hardware.sim`     the simulated lab: ``make_sim_lab(cfg, surface) -> Lab``

See ``docs/simulator.md``. This package may import :mod:`tactile`, never ``protocols`` or ``analysis``.
"""
