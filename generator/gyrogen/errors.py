"""The one exception gyrogen raises for the user's mistakes and missing tools.

Its message is a single line that names what is wrong and why; the CLI prints
it and exits non-zero without a traceback.
"""


class GyrogenError(Exception):
    exit_code = 1


class BuildError(GyrogenError):
    """A compiler is missing or refused the generated code."""


class SceneError(GyrogenError):
    """A scene file that cannot be read or is not physical."""

    exit_code = 2


class SetupRefused(SceneError, ValueError):
    """<prefix>_setup refused a parameter set (its code and why). A ValueError
    too, for the Python API's callers; callers that know where the values
    came from add it (simulate.parameters, --param)."""
