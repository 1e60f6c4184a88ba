"""Errors a user can act on. The command line prints them as one message, never a traceback."""


class LirmUserError(Exception):
    """Bad input or a missing prerequisite: `str(err)` names the file and says what to do."""


class AssetLoadError(LirmUserError):
    """A 3D model file could not be loaded."""


class EnvironmentLoadError(LirmUserError):
    """An HDR environment file could not be loaded."""
