"""Worlds the sequencer acts on: simulated bins (and their costs).  A real cell is reached through the service."""

from opportune.worlds.bins import BIN_NAMES, BINS, ConveyorBin, PalletWorld, PileBin, UniformBin, WeightedBin, World, make_world
from opportune.worlds.costs import CellModel, TimeModel

__all__ = ["BIN_NAMES", "BINS", "CellModel", "ConveyorBin", "PalletWorld", "PileBin", "TimeModel", "UniformBin", "WeightedBin", "World",
           "make_world"]
