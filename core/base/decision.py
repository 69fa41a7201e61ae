"""A decision a stage took, typed: what was chosen and why (never a string to parse)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Decision:
    """`choice` is a plain value (str, number, bool) that code may compare; `reason` is for people."""

    choice: Any
    reason: str

    def to_dict(self) -> dict:
        return {"choice": self.choice, "reason": self.reason}


def decisions_to_dict(decisions: dict) -> dict:
    """A report's JSON form of a {name: Decision | value} mapping."""
    return {k: v.to_dict() if isinstance(v, Decision) else v for k, v in decisions.items()}
