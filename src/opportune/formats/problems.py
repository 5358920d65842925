"""Problems found in a plan: where, what, and what to do about it."""

from __future__ import annotations

from dataclasses import dataclass, field

#: The control characters no text of a plan, a request or a terminal line may hold, as the body of a
#: regular-expression class: C0 but tab, line feed and carriage return, DEL, and C1 (an ESC sequence would
#: act on a terminal; PostgreSQL refuses U+0000).
CONTROL_CHARS = "\x00-\x08\x0b\x0c\x0e-\x1f\x7f-\x9f"
#: Text without those characters, as a regular expression's source (JSON Schema's ``pattern``, Python's
#: ``re`` and Pydantic's engine read it alike): what the JSON Schema and the OpenAPI document state.
PRINTABLE = "^[^\\x00-\\x08\\x0b\\x0c\\x0e-\\x1f\\x7f-\\x9f]*$"


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


def closest(word: str, choices) -> str | None:
    """The one of ``choices`` a misspelt ``word`` most likely meant, or None: the same text but for case
    first, else the closest by :func:`difflib.get_close_matches` (case folded).  The command line's and the
    service's "did you mean" both come from here.

    Parameters
    ----------
    word : str
        What was given.
    choices : iterable of str
        What it could have been.

    Returns
    -------
    str or None
        The choice, as it is spelt among ``choices``; None when nothing is close.

    Examples
    --------
    >>> closest("RL", ["ca", "rl"]), closest("cace", ["ca", "ba"]), closest("zz", ["ca"])
    ('rl', 'ca', None)
    """
    import difflib     # loaded only when there is a mistake to suggest a correction for

    folded: dict[str, str] = {}
    for choice in choices:
        folded.setdefault(choice.casefold(), choice)
    key = word.casefold()
    if key in folded:
        return folded[key]
    guess = difflib.get_close_matches(key, list(folded), n=1)
    return folded[guess[0]] if guess else None


def did_you_mean(word: str, choices, quote: str = "'") -> str:
    """``"did you mean 'x'? "`` for :func:`closest`, or ``""`` when nothing is close.

    Examples
    --------
    >>> did_you_mean("rll", ["ca", "rl"]) + "declare it"
    "did you mean 'rl'? declare it"
    """
    guess = closest(word, choices)
    return f"did you mean {quote}{guess}{quote}? " if guess is not None else ""


#: Ids a message lists at most (a plan has up to 10,000 parts: a message names the first of them).
LISTED = 20


def listing(ids) -> str:
    """``"a, b, c"``: at most :data:`LISTED` ids, then how many more.

    Examples
    --------
    >>> listing(["a", "b"]), listing(str(i) for i in range(25))[-21:]
    ('a, b', '18, 19, … (25 in all)')
    """
    ids = list(ids)
    more = f", … ({len(ids):,} in all)" if len(ids) > LISTED else ""
    return ", ".join(ids[:LISTED]) + more


def unknown_part_hint(part: str, known, what: str = "the plan's parts") -> str:
    """What to say about an unknown part id: the part it most likely meant, and the ids there are.

    Examples
    --------
    >>> unknown_part_hint("rll", ["ca", "rl"])
    "did you mean 'rl'? the plan's parts are ca, rl"
    """
    known = list(known)
    return did_you_mean(part, known) + f"{what} are {listing(known)}"
