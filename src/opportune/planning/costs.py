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
    """What each robot action costs, in the paper's accounting (unit motions, not seconds).

    Parameters
    ----------
    motion : float, default 1.0
        One robot motion: bin → assembly, bin → buffer or buffer → assembly.
    shake : float, default 1.0
        One shake of the bin.
    look : float, default 0.0
        One look.
    parts : mapping of str to float, optional
        A part's own motion cost (a heavy part moves slowly).

    Raises
    ------
    ValueError
        If a cost is negative.

    Examples
    --------
    >>> costs = TimeModel(look=0.1, parts={"co": 3.0})
    >>> costs.move("co"), costs.move("ca"), costs.look
    (3.0, 1.0, 0.1)
    """

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
        """Cost of one robot motion carrying ``part``.

        Parameters
        ----------
        part : str
            The part carried.

        Returns
        -------
        float
            The part's own motion cost, else :attr:`motion`.

        Examples
        --------
        >>> TimeModel(parts={"co": 3.0}).move("co")
        3.0
        """
        return self.parts.get(part, self.motion)

    @classmethod
    def from_plan(cls, plan, **overrides) -> "TimeModel":
        """The plan file's ``simulation.costs``, with command-line overrides.

        Parameters
        ----------
        plan : Plan
            The plan (its ``simulation`` settings).
        **overrides
            ``motion``, ``shake`` or ``look`` values that replace the file's (``None``: keep the file's).

        Returns
        -------
        TimeModel
            The costs.

        Raises
        ------
        ValueError
            If the costs name a part the plan does not have, or a cost is negative.

        Examples
        --------
        >>> from opportune import load_plan
        >>> TimeModel.from_plan(load_plan("example:gearbox"), shake=2.0).shake
        2.0
        """
        costs = dict(plan.simulation.get("costs", {}) or {})
        values = {k: costs[k] for k in ("motion", "shake", "look") if k in costs}
        values.update({k: v for k, v in overrides.items() if v is not None})
        unknown = set(costs.get("parts", {}) or {}) - set(plan.part_ids)
        if unknown:
            raise ValueError(f"simulation.costs.parts names unknown part(s): {', '.join(sorted(unknown))}")
        return cls(parts=dict(costs.get("parts", {}) or {}), **values)

    def to_dict(self) -> dict:
        """The costs as JSON values (a study's recorded settings).

        Returns
        -------
        dict
            ``motion``, ``shake``, ``look`` and ``parts``.

        Examples
        --------
        >>> TimeModel().to_dict()
        {'motion': 1.0, 'shake': 1.0, 'look': 0.0, 'parts': {}}
        """
        return {"motion": self.motion, "shake": self.shake, "look": self.look, "parts": dict(self.parts)}


#: The durations a plan's ``simulation.cell.parts`` may give per part.
PART_DURATIONS = ("pick", "place", "install")
MAX_CELL_VALUE = 1e6   # seconds or metres: no cell takes a million seconds a motion (a typo, refused)


@dataclass(frozen=True)
class CellModel:
    """A cell's times, for cycle times in seconds (beside the unit motions of :class:`TimeModel`).

    The robot moves at ``speed`` (m/s, mean over a motion, acceleration included) between three
    stations ``bin_fixture``, ``bin_buffer`` and ``buffer_fixture`` metres apart.  A motion is a pick
    (``pick`` s), the loaded travel, the part put down (``install`` s on the assembly, ``place`` s in a
    buffer location) and the empty return to the bin, as long as the travel there:

    * install from the bin: ``pick + 2 × bin_fixture / speed + install``;
    * install from the buffer: ``pick + (buffer_fixture + bin_fixture + bin_buffer) / speed + install``
      (the robot goes from the bin to the buffer, to the fixture and back to the bin);
    * buffer a part: ``pick + 2 × bin_buffer / speed + place``;
    * a look: ``camera`` s (image and recognition); a shake: ``shake`` s, the heap's settling included.

    ``parts`` gives a part its own ``pick``, ``place`` or ``install`` seconds (a heavy cover is slow to
    fit).  The defaults are a small cell's: 0.5 m/s, stations 0.6, 0.4 and 0.5 m apart, 1 s a pick,
    0.8 s a place, 2 s an install, 0.5 s a look, 3 s a shake.  O(1) per motion.

    >>> cell = CellModel(parts={"co": {"install": 4.0}})
    >>> [round(s, 2) for s in (cell.install_seconds("co", "bin"), cell.install_seconds("ca", "bin"),
    ...                        cell.install_seconds("ca", "buffer"), cell.buffer_seconds("ca"))]
    [7.4, 5.4, 6.0, 3.4]
    """

    speed: float = 0.5
    bin_fixture: float = 0.6
    bin_buffer: float = 0.4
    buffer_fixture: float = 0.5
    pick: float = 1.0
    place: float = 0.8
    install: float = 2.0
    camera: float = 0.5
    shake: float = 3.0
    parts: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def __post_init__(self):
        for f in ("speed", "bin_fixture", "bin_buffer", "buffer_fixture", "pick", "place", "install", "camera",
                  "shake"):
            value = getattr(self, f)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= MAX_CELL_VALUE:
                raise ValueError(f"cell.{f} must be a number from 0 to {MAX_CELL_VALUE:g}, not {value!r}")
        if not self.speed > 0:
            raise ValueError("cell.speed must be above 0 (metres per second)")
        for part, times in self.parts.items():
            for k, v in dict(times).items():
                if k not in PART_DURATIONS:
                    raise ValueError(f"cell.parts.{part}: unknown duration '{k}': give {', '.join(PART_DURATIONS)}")
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= MAX_CELL_VALUE:
                    raise ValueError(f"cell.parts.{part}.{k} must be a number of seconds from 0 to "
                                     f"{MAX_CELL_VALUE:g}, not {v!r}")

    def _of(self, part: str, what: str) -> float:
        return float(self.parts.get(part, {}).get(what, getattr(self, what)))

    def install_seconds(self, part: str, source: str) -> float:
        """Seconds to install one unit of ``part`` from ``source`` (``"bin"`` or ``"buffer"``)."""
        travel = (2 * self.bin_fixture if source == "bin"
                  else self.bin_buffer + self.buffer_fixture + self.bin_fixture)
        return self._of(part, "pick") + travel / self.speed + self._of(part, "install")

    def buffer_seconds(self, part: str) -> float:
        """Seconds to move one unit of ``part`` from the bin to a buffer location."""
        return self._of(part, "pick") + 2 * self.bin_buffer / self.speed + self._of(part, "place")

    @classmethod
    def from_dict(cls, values: Mapping | None, known_parts=None) -> "CellModel":
        """A cell model from a plan's ``simulation.cell`` or a study's settings (missing keys: the defaults);
        ``ValueError`` on a bad value or, with ``known_parts``, a part the plan does not have."""
        values = dict(values or {})
        unknown = set(values) - {f for f in cls.__dataclass_fields__}
        if unknown:
            raise ValueError(f"cell: unknown setting(s) {', '.join(sorted(map(str, unknown)))}")
        parts = {str(k): dict(v or {}) for k, v in dict(values.pop("parts", None) or {}).items()}
        if known_parts is not None and set(parts) - set(known_parts):
            raise ValueError(f"simulation.cell.parts names unknown part(s): "
                             f"{', '.join(sorted(set(parts) - set(known_parts)))}")
        return cls(parts=parts, **values)

    @classmethod
    def from_plan(cls, plan) -> "CellModel":
        """The plan file's ``simulation.cell`` (the defaults where it says nothing); ``ValueError`` if malformed."""
        return cls.from_dict(plan.simulation.get("cell"), plan.part_ids)

    def to_dict(self) -> dict:
        doc = {f: getattr(self, f) for f in self.__dataclass_fields__ if f != "parts"}
        doc["parts"] = {k: dict(v) for k, v in self.parts.items()}
        return doc
