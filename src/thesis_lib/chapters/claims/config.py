"""The Claims page's parameters: :class:`Config`.

Used in: the Claims page of the book.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Config"]


@dataclass
class Config:
    """Parameters of the Claims page."""

    claims_csv: str = ""
    """``studies/claims.csv`` of the checkout when empty."""
