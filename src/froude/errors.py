"""One exception hierarchy. The CLI turns every FroudeError into a one-line message and exit 2."""


class FroudeError(Exception):
    """Base class of every error froude raises on purpose (bad input, impossible request)."""


class BvhError(FroudeError):
    """A BVH file could not be read or written. The message names the file and line."""

    def __init__(self, message: str, path: str | None = None, line: int | None = None):
        self.path = path
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        super().__init__(where + message)


class NotARunningMotion(FroudeError):
    """The motion has no flight phase, no forward progression or too few stances to fit."""


class FitError(FroudeError):
    """The simple machine could not be fitted to the motion."""


class IkError(FroudeError):
    """Inverse kinematics could not reach its targets; the message names frame and residual."""


class CharacterError(FroudeError):
    """A character description is invalid (unknown preset, bad numbers, topology mismatch)."""


class PlanError(FroudeError):
    """A speed or acceleration goal cannot be met; the message says what can."""
