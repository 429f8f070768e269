"""Wire-protocol emulators of the lab's devices, for tests and rehearsals on loopback.

Each emulator speaks the real device's protocol so the real client library can be tested
against it; see ``docs/ur10.md`` for the UR controller. Imports are lazy so that
``python -m tactile_flow.hardware.emulators.ur_controller`` runs the module once.
"""

__all__ = ["URControllerConfig", "URControllerEmulator", "URControllerProcess"]


def __getattr__(name):
    if name in __all__:
        from . import ur_controller
        return getattr(ur_controller, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
