"""The Survey page's parameters: :class:`Config`.

Used in: the Survey page of the book (thesis ch. 3).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Config"]


@dataclass
class Config:
    """Parameters of the survey page."""

    top: int = 12
    """How many values each bar chart shows."""

    def __post_init__(self) -> None:
        if not isinstance(self.top, int) or self.top < 1:
            raise ValueError(f"top must be a positive integer, got {self.top!r}")
