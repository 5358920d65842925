"""What ``opportune derive`` shows beside the plan: the explanation (``--explain``), the exploded view
(``--figure``) and the notes on shapes the plan does not carry."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Shown:
    """The ``--json`` additions (``data``), the explanation's text and the notes for standard error."""

    data: dict = field(default_factory=dict)
    text: str = ""
    notes: list[str] = field(default_factory=list)


def show(derivation, *, explain: bool = False, figure: str | Path | None = None, strategy: int = 1) -> Shown:
    """Explain a derivation and draw its figure, as the command asks.

    Parameters
    ----------
    derivation : Derivation
        What :func:`opportune.derive.derive` returned.
    explain : bool
        Explain the plan (:func:`opportune.derive.explain.explain`).
    figure : str or Path, optional
        Draw the exploded view there (:func:`opportune.derive.figure.exploded`).
    strategy : int
        The strategy the figure explodes, from 1.

    Returns
    -------
    Shown
        What to print.

    Raises
    ------
    ValueError
        A figure's suffix or strategy that cannot be drawn (checked before anything is drawn), or a figure
        file that cannot be written.

    Examples
    --------
    >>> from opportune.derive import derive
    >>> shown = show(derive("geometry:gearbox"), explain=True)
    >>> shown.text.splitlines()[0]
    'gearbox: 14 parts, 10 strategies'
    """
    out = Shown(notes=list(derivation.notes))
    if figure is not None:
        from opportune.derive.figure import exploded

        try:
            written = exploded(derivation, figure, strategy=strategy)
        except OSError as exc:
            raise ValueError(f"{figure}: cannot write the figure ({exc.strerror or exc}); give a path in a folder "
                             "you can write to") from None
        out.data["figure"] = str(written)
        what = "one feasible sequence" if derivation.plan.is_ways else f"strategy s{strategy}"
        out.notes.append(f"wrote the exploded view ({what}) to {written}")
    if explain:
        from opportune.derive.explain import explain as explain_plan

        explanation = explain_plan(derivation, derivation.assembly)
        out.data["explanation"] = explanation.to_dict()
        out.text = explanation.text()
    if derivation.notes:
        out.data["notes"] = list(derivation.notes)
    return out
