"""Worlds the sequencer acts on: simulated bins (and their costs).  A real cell is reached through the service."""

from opportune.worlds.bins import BINS, ConveyorBin, PalletWorld, PileBin, UniformBin, WeightedBin, World, make_world
from opportune.worlds.costs import TimeModel

__all__ = ["BINS", "ConveyorBin", "PalletWorld", "PileBin", "TimeModel", "UniformBin", "WeightedBin", "World",
           "make_world"]
