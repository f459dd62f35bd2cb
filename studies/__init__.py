"""Research studies of the project: one folder each (not installed; see README.md)."""
