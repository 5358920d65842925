"""The time model: what each robot action costs.

Default (the paper's accounting): every robot motion — bin → assembly,
bin → buffer, buffer → assembly — costs 1, a shake costs 1, a look costs 0.
Motions can be priced per part (a heavy part moves slowly).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping


@dataclass(frozen=True)
class TimeModel:
    motion: float = 1.0
    shake: float = 1.0
    look: float = 0.0
    parts: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        for name in ("motion", "shake", "look"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} cost must be ≥ 0")
        if any(v < 0 for v in self.parts.values()):
            raise ValueError("per-part motion costs must be ≥ 0")

    def move(self, part: str) -> float:
        """Cost of one robot motion carrying ``part``."""
        return self.parts.get(part, self.motion)

    @classmethod
    def from_plan(cls, plan, **overrides) -> "TimeModel":
        """The plan file's ``simulation.costs`` with command-line overrides (``None`` = keep)."""
        costs = dict(plan.simulation.get("costs", {}) or {})
        values = {k: costs[k] for k in ("motion", "shake", "look") if k in costs}
        values.update({k: v for k, v in overrides.items() if v is not None})
        unknown = set(costs.get("parts", {}) or {}) - set(plan.part_ids)
        if unknown:
            raise ValueError(f"simulation.costs.parts names unknown part(s): {', '.join(sorted(unknown))}")
        return cls(parts=dict(costs.get("parts", {}) or {}), **values)

    def to_dict(self) -> dict:
        return {"motion": self.motion, "shake": self.shake, "look": self.look, "parts": dict(self.parts)}
