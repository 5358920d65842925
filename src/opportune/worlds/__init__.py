"""Worlds the sequencer acts on: simulated bins (and their costs).  A real cell is reached through the service."""

from __future__ import annotations

from opportune.planning.costs import CellModel, TimeModel
from opportune.worlds.bins import ConveyorBin, PalletWorld, PileBin, UniformBin, WeightedBin, World

# not typing.TYPE_CHECKING: importing typing costs 5 ms of every command's start-up
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = ["BIN_NAMES", "BINS", "CellModel", "ConveyorBin", "PalletWorld", "PileBin", "TimeModel", "UniformBin", "WeightedBin", "World",
           "make_world"]


BINS = {"uniform": UniformBin, "weighted": WeightedBin, "pile": PileBin, "conveyor": ConveyorBin}


#: Every bin model by name: those of :data:`BINS` and the physical bin (:mod:`opportune.worlds.physics`, MuJoCo).
BIN_NAMES = (*BINS, "physics")


def make_world(kind: str, *, visible: int = 2, weights: Mapping[str, float] | None = None,
               geometry: Mapping[str, tuple] | None = None, physics: Mapping | None = None) -> World:
    """A bin model by name.

    O(1); the physical bin builds its model at its first trial.

    Parameters
    ----------
    kind : str
        ``uniform``, ``weighted``, ``pile``, ``conveyor`` or ``physics`` (:data:`BIN_NAMES`).
    visible : int, default 2
        Units seen per look.
    weights : mapping of str to float, optional
        The weighted bin's visibilities.
    geometry : mapping of str to tuple, optional
        The physical bin's shapes: part id → ``(shape, dimensions)``.
    physics : mapping, optional
        The physical bin's settings (``bin``, ``settle_steps``, ``visible_fraction``: a plan's
        ``simulation.physics``).

    Returns
    -------
    World
        A new bin, empty until :meth:`~opportune.worlds.bins.World.reset`.

    Raises
    ------
    ValueError
        If ``kind`` is not a bin model's name, or ``visible`` is below 1.

    Examples
    --------
    >>> make_world("pile", visible=3).name
    'pile'
    >>> make_world("tray")
    Traceback (most recent call last):
        ...
    ValueError: unknown bin model 'tray': use one of uniform, weighted, pile, conveyor, physics
    """
    if kind == "physics":
        from opportune.worlds.physics import PhysicsBin

        settings = dict(physics or {})
        if "bin" in settings:
            settings["bin_size"] = settings.pop("bin")
        return PhysicsBin(visible, geometry, **settings)
    if kind not in BINS:
        raise ValueError(f"unknown bin model '{kind}': use one of {', '.join(BIN_NAMES)}")
    if kind == "weighted":
        return WeightedBin(visible, weights)
    return BINS[kind](visible)
