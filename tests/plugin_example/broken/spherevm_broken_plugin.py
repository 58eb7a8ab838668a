"""An entry point that names a class which is not a spherevm operation (tests/test_plugins.py)."""


class NotAPlugin:
    """Derives from none of Force, Integrator, Updater, Writer: spherevm.plugins.load refuses it."""
