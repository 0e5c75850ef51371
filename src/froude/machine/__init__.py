"""The simple machines: the running one (dimensionless dynamics, control fit, limit cycle, transition table)
and the walking one (``walking``, ``walk_model``, ``walk_fit``, ``walk_speed``)."""


def is_walking(machine) -> bool:
    """Whether a fitted machine is the walking one (``froude.walking/1``) rather than the running one.

    Here rather than in ``walk_model`` so that a run's verbs tell the machines apart without importing the
    walking code (``froude scale`` of a run never needs it)."""
    return getattr(machine, "kind", "running") == "walking"
