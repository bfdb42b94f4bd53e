"""One exception family for every user-facing fault.

The CLI catches ZflocError, prints its message on one line and exits 2; anything else
escaping is a bug. Messages name the offending thing (file, key, frame, array).
"""


class ZflocError(Exception):
    """Base of every error the package raises on purpose."""


class ConfigError(ZflocError):
    """A settings file or override is malformed, has an unknown key or a bad value."""


class FloorplanError(ZflocError):
    """A floorplan cannot be read or is unusable (missing file, bad YAML, no walls).
    Always one line: messages quoting a parser's own (multi-line) error are flattened."""

    def __init__(self, message: str = ""):
        super().__init__(" ".join(str(message).split()) if "\n" in str(message) or "\r" in str(message) else message)


class InputError(ZflocError):
    """Input data is invalid: NaN points, empty BEV, bad frame shapes, unreadable source."""


class FrameError(InputError):
    """One frame is invalid; inside a stream it is skipped with a logged reason."""


class SessionLogError(InputError):
    """An MCAP session file is missing, corrupt, truncated or lacks required topics."""


class BackboneError(ZflocError):
    """A pretrained network cannot be used: the [torch] extra is missing, the model folder
    or hub id cannot be found, or the model is not of the kind asked for."""


class UsageError(ZflocError):
    """The API is used out of order: a closed Localizer is pushed a frame, or two threads
    push into one Localizer at once."""
