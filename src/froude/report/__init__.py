"""The physics report: its measures and bars (metrics), the walking and path sections."""
