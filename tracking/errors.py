"""Errors a user can act on. Each message says what was wrong, where, and how to fix it."""


class SessionError(ValueError):
    """A recording's session.json (or an anchors block) is invalid; the message names the field."""


class SourceError(RuntimeError):
    """A camera, video or recording cannot be opened or stopped delivering frames."""


class CalibrationError(ValueError):
    """A calibration file is missing, unreadable or inconsistent."""
