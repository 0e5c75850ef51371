"""The simple running machine: dimensionless dynamics, control fit, limit cycle, transition table."""
