"""Problems found in a plan: where, what, and what to do about it."""

from __future__ import annotations

from dataclasses import dataclass, field

#: The control characters no text of a plan, a request or a terminal line may hold, as the body of a
#: regular-expression class: C0 but tab, line feed and carriage return, DEL, and C1 (an ESC sequence would
#: act on a terminal; PostgreSQL refuses U+0000).
CONTROL_CHARS = "\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f"


@dataclass(frozen=True)
class Problem:
    """One finding about a plan file.

    ``severity`` is ``"error"`` (the plan cannot be used) or ``"warning"``
    (usable, but probably not what was meant).  ``line`` is 1-based where the
    format gives one; ``parts`` names the part ids involved.
    """

    message: str
    hint: str = ""
    file: str | None = None
    line: int | None = None
    parts: tuple[str, ...] = field(default_factory=tuple)
    severity: str = "error"
    code: str = "invalid"

    @property
    def where(self) -> str:
        if self.file and self.line:
            return f"{self.file}:{self.line}"
        return self.file or (f"line {self.line}" if self.line else "")

    def __str__(self) -> str:
        head = f"{self.where}: " if self.where else ""
        tail = f" — {self.hint}" if self.hint else ""
        return f"{head}{self.severity}: {self.message}{tail}"

    def to_dict(self) -> dict:
        return {
            "severity": self.severity,
            "code": self.code,
            "message": self.message,
            "hint": self.hint,
            "file": self.file,
            "line": self.line,
            "parts": list(self.parts),
        }
