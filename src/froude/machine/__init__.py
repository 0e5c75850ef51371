"""The simple machines: the running one (dimensionless dynamics, control fit, limit cycle, transition table)
and the walking one (``walking``, ``walk_model``, ``walk_cycle``, ``walk_fit``, ``walk_speed``). Which one
models a clip, and what the verbs ask of it, is ``froude.flow.kinds``'s."""
