"""Constitutive-law discovery from a user's own observation file (the ``observed`` task)."""

from tasks.observed.task import ObservedTask

__all__ = ["ObservedTask"]
