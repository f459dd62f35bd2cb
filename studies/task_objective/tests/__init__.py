"""Tests of the task-objective study."""
