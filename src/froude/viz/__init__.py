"""Pictures: plots (matplotlib) and renders. Optional extras, imported lazily."""
