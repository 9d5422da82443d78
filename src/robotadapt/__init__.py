"""robotadapt."""
