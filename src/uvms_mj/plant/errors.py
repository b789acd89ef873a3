"""The plant's one error type (raised by every loader, override and initial state)."""

from __future__ import annotations

__all__ = ["ParameterError"]


class ParameterError(ValueError):
    """A model file or parameter that is missing, malformed or non-physical."""
