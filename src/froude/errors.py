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


class NotAWalkingMotion(FroudeError):
    """The walking machine cannot be fitted to the motion: it is not a walk (it runs, stays in place) or has
    no complete walking step (a touchdown, the other foot's liftoff, the next touchdown)."""


class FitError(FroudeError):
    """The simple machine could not be fitted to the motion."""


class PastWalkRunTransition(FitError):
    """A walk asked past the walk-run transition (Froude number U > 0.7): people run there. The message says
    the fastest walking speed in m/s; known from the machine alone, so a refusal needs no search of the
    reachable speeds."""


class IkError(FroudeError):
    """Inverse kinematics could not reach its targets; the message names frame and residual."""


class CharacterError(FroudeError):
    """A character description is invalid (unknown preset, bad numbers, topology mismatch)."""


class PlanError(FroudeError):
    """A speed or acceleration goal cannot be met; the message says what can.

    When the planner knows what is reachable it says so in dimensionless apex speeds U (the machine's own
    units; the pipeline turns them into m/s for the character): ``U_goal``, ``U_start``, ``U_one_step``
    (the fastest, or slowest, apex speed one step from the start reaches), ``U_sustainable`` (lo, hi),
    ``steps_needed`` (None when more steps would not help) and ``steps_enough`` (a number of steps that is
    known to do, not necessarily the fewest). Any of them may be None.
    """

    def __init__(self, message: str, *, U_goal=None, U_start=None, U_one_step=None, U_sustainable=None,
                 steps_needed=None, steps_enough=None):
        super().__init__(message)
        self.steps_enough = steps_enough
        self.U_goal = U_goal
        self.U_start = U_start
        self.U_one_step = U_one_step
        self.U_sustainable = U_sustainable
        self.steps_needed = steps_needed


class BeyondHumanRange(FroudeError):
    """A speed beyond what a human of the character's size runs (the human speed law's limits: step length,
    step frequency, stance time); the message says the human limit in m/s. ``--unlimited`` (the API's
    ``unlimited=True``) lifts it."""
