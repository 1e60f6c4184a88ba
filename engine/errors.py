"""Errors a user can act on. The command line prints them as one message, never a traceback, and
exits with a code that tells them apart (engine/cli.py, README "Exit codes"): LirmUsageError 2,
LirmUserError 3, LirmResourceError 4."""


class LirmUserError(Exception):
    """Bad input or a missing prerequisite: `str(err)` names the file and says what to do."""


class LirmUsageError(LirmUserError):
    """A command-line option out of its range or options that do not go together: `str(err)` names
    the option, what it accepts and the value given."""


class AssetLoadError(LirmUserError):
    """A 3D model file could not be loaded."""


class EnvironmentLoadError(LirmUserError):
    """An HDR environment file could not be loaded."""


class LirmResourceError(LirmUserError):
    """Not enough memory or disk for what was asked: `str(err)` says how much is needed, how much
    there is, and what to lower or free."""
