"""Every error a user can cause, all under :class:`ImupipeError`.

The command line turns each into one line on stderr and exit code 2 (never a traceback); a
``ValueError`` or ``FileNotFoundError`` that reaches it is a bug in imupipe.  Lower layers
raise the most specific class; a layer boundary re-raises with context (``raise ... from``).
"""


class ImupipeError(Exception):
    """A problem with the user's input or request, stated in one sentence."""


class InputError(ImupipeError):
    """The input is not something imupipe can read (not a file, not MCAP, no IMU topic...)."""


class NotMcapError(InputError):
    """The file does not start with the MCAP magic."""


class TooFewFramesError(ImupipeError):
    """The usable data is too short for even the shortest averaging time."""


class ConfigError(ImupipeError):
    """A device configuration the ADIS16364 cannot take (rate, range, filter)."""


class ScenarioError(ImupipeError):
    """A scenario TOML file that cannot be read or names impossible values."""


class DeviceError(ImupipeError):
    """The SPI device is missing, is not an ADIS16364, or does not accept its configuration."""


class SelfTestError(DeviceError):
    """The ADIS16364's self-test or start-up status check (DIAG_STAT) reports a fault."""


class ViewerError(ImupipeError):
    """No Rerun recording to show, or no Rerun viewer to show it with."""


class DatasheetError(ImupipeError):
    """A datasheet TOML file (N, B, K, rms per sensor with units) that cannot be read."""


class ExportError(ImupipeError):
    """A result folder or option an export cannot use."""


class OutputError(ImupipeError):
    """``--out`` cannot receive an analysis (a file, a dangling link, a foreign folder...)."""


class FleetError(ImupipeError):
    """A fleet that cannot start (no recordings found, no scheduler) or whose units failed."""
