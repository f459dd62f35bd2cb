"""The task-objective study: the score of urban_canyon_v1 and what reaches it (README.md)."""
