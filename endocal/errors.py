"""Domain errors (and the one warning a model gives).

Every error a user can cause subclasses a builtin (so library callers can catch
``ValueError`` or ``OSError`` as usual) and :class:`EndocalError` (so the CLI can
turn it into one line and exit code 2). Messages say what was wrong, where, and
what to do.
"""


class EndocalError(Exception):
    """Base of every user-facing endocal error."""


class ConfigError(EndocalError, ValueError):
    """A probe, simulator or protocol configuration is malformed or out of range."""


class ProtocolError(EndocalError, ValueError):
    """An excitation protocol is unknown, malformed, or asks for an impossible motion."""


class LimitError(EndocalError, ValueError):
    """A command lies beyond the probe's knob, translation or rotation limits."""


class RunFormatError(EndocalError, ValueError):
    """A run folder or aligned table does not follow the run format."""


class OutputExistsError(EndocalError, FileExistsError):
    """An output path exists and ``force`` was not given."""


class OutputPathError(EndocalError, OSError):
    """An output path cannot be created or written."""


class OutOfRangeWarning(UserWarning):
    """Commands beyond a model's fitted range were clamped (``out_of_range="clamp"``)."""


class HardwareError(EndocalError, RuntimeError):
    """A hardware device failed, is missing, or answered out of range."""


class ModelError(EndocalError, ValueError):
    """A model file or fit request is invalid (wrong version, fields, axis, or data)."""


class CompensationRefusedError(ModelError):
    """A fitted model predicts, but its base's inverse does not converge (checked on a sweep): no compensation."""


class StopSignal(SystemExit):
    """A termination signal (SIGTERM, SIGHUP) stopped a hardware run, after torque was switched off.

    Not an error of the user's: it unwinds like ``sys.exit(128 + signum)`` so that every
    ``finally`` still runs (the run's streams are flushed, ``run.json`` says how it ended).
    """

    def __init__(self, signum: int) -> None:
        import signal

        super().__init__(128 + signum)
        self.signum = signum
        try:
            self.signame = signal.Signals(signum).name
        except ValueError:
            self.signame = f"signal {signum}"
