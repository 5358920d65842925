"""Bin models: what the camera sees at each look, and how the bin reacts to picks and shakes.

Every world holds the units still in the bin (part ids, with repeats for
quantities) and answers three calls: :meth:`look` (the visible parts now),
:meth:`take` (a visible unit leaves the bin) and :meth:`shake`.  All
randomness comes from the ``random.Random`` given to :meth:`reset`, so a trial
is reproduced exactly by its seed.
"""

from __future__ import annotations

import random
from typing import Mapping, Sequence


class World:
    """Base class: a bin of units and a camera that sees ``visible`` of them at a time.

    A subclass defines :meth:`look` (and :meth:`take` and :meth:`shake` where the bin reacts
    otherwise); :func:`~opportune.worlds.make_world` makes the package's by name.

    Parameters
    ----------
    visible : int, default 2
        Units seen per look (fewer when fewer are left).

    Raises
    ------
    ValueError
        If ``visible`` is below 1.

    Examples
    --------
    >>> import random
    >>> bin = UniformBin(visible=2)
    >>> bin.reset(["a", "a", "b", "c"], random.Random(1))
    >>> bin.look(), len(bin)
    (('a', 'c'), 4)
    """

    name = "world"
    markov = False  # True if each look depends only on the bin's contents (the optimum's assumption)

    def __init__(self, visible: int = 2):
        if visible < 1:
            raise ValueError("visible must be at least 1")
        self.visible = visible
        self.units: list[str] = []
        self.rng = random.Random(0)

    def reset(self, units: Sequence[str], rng: random.Random) -> None:
        """Fill the bin with ``units`` for a new trial.

        Parameters
        ----------
        units : sequence of str
            Part ids, one per unit (repeats for quantities).
        rng : random.Random
            The trial's source of randomness: every look and shake draws from it, so a trial is
            reproduced exactly by its seed.

        Examples
        --------
        >>> import random
        >>> bin = PileBin(visible=2)
        >>> bin.reset(["a", "b", "c"], random.Random(0))
        >>> bin.look()
        ('a', 'c')
        """
        self.units = list(units)
        self.rng = rng

    def look(self) -> tuple[str, ...]:
        """The units visible now.

        Returns
        -------
        tuple of str
            Part ids of the visible units (a part once per visible unit).

        Raises
        ------
        NotImplementedError
            In the base class: each bin model defines its own.

        Examples
        --------
        >>> import random
        >>> bin = ConveyorBin(visible=1)
        >>> bin.reset(["a", "b", "c"], random.Random(0))
        >>> bin.look(), bin.look(), bin.look()
        (('a',), ('c',), ('b',))
        """
        raise NotImplementedError

    def take(self, part: str) -> None:
        """A unit of ``part`` (one that was visible) leaves the bin.

        Parameters
        ----------
        part : str
            The part taken.

        Examples
        --------
        >>> import random
        >>> bin = UniformBin(visible=2)
        >>> bin.reset(["a", "a", "b", "c"], random.Random(1))
        >>> bin.take("a")
        >>> len(bin), sorted(bin.units)
        (3, ['a', 'b', 'c'])
        """
        self.units.remove(part)

    def shake(self) -> None:
        """Disturb the bin; the next look is fresh (the base class's bin needs nothing done).

        Examples
        --------
        >>> import random
        >>> bin = PileBin(visible=2)
        >>> bin.reset(["a", "b", "c"], random.Random(0))
        >>> bin.shake()
        >>> sorted(bin.units)
        ['a', 'b', 'c']
        """

    def __len__(self) -> int:
        return len(self.units)


class UniformBin(World):
    """Each look shows ``visible`` units drawn uniformly without replacement.

    Looks are independent (parts shift after every pick), so a shake just buys a fresh look.

    Parameters
    ----------
    visible : int, default 2
        Units seen per look.

    Examples
    --------
    >>> import random
    >>> bin = UniformBin(visible=2)
    >>> bin.reset(["a", "b", "c"], random.Random(0))
    >>> len(bin.look())
    2
    """

    name = "uniform"
    markov = True

    def look(self) -> tuple[str, ...]:
        units = self.units
        n = len(units)
        k = self.visible
        if n <= k:
            return tuple(units)
        random_ = self.rng.random
        if k == 2:  # the common case, without random.sample's overhead
            i = int(random_() * n)
            j = int(random_() * (n - 1))
            return (units[i], units[j + (j >= i)])
        picked = set()
        out = []
        while len(out) < k:
            i = int(random_() * n)
            if i not in picked:
                picked.add(i)
                out.append(units[i])
        return tuple(out)


class WeightedBin(World):
    """As :class:`UniformBin`, but units are drawn with per-part visibility weights (big parts show
    more often): successive sampling without replacement.

    Parameters
    ----------
    visible : int, default 2
        Units seen per look.
    weights : mapping of str to float, optional
        Each part's visibility (absent parts: 1).

    Examples
    --------
    >>> import random
    >>> bin = WeightedBin(visible=1, weights={"a": 1000.0})
    >>> bin.reset(["a", "b"], random.Random(3))
    >>> bin.look()
    ('a',)
    """

    name = "weighted"
    markov = True

    def __init__(self, visible: int = 2, weights: Mapping[str, float] | None = None):
        super().__init__(visible)
        self.weights = dict(weights or {})

    def look(self) -> tuple[str, ...]:
        units = self.units
        if len(units) <= self.visible:
            return tuple(units)
        idx = list(range(len(units)))
        w = [self.weights.get(p, 1.0) for p in units]
        out = []
        for _ in range(self.visible):
            r = self.rng.random() * sum(w[i] for i in idx)
            for j, i in enumerate(idx):
                r -= w[i]
                if r < 0 or j == len(idx) - 1:
                    out.append(units[i])
                    idx.pop(j)
                    break
        return tuple(out)


class PileBin(World):
    """A random stack: the top ``visible`` units are seen; taking one uncovers the next; a shake
    reshuffles the stack.

    Parameters
    ----------
    visible : int, default 2
        Units seen on top.

    Examples
    --------
    >>> import random
    >>> bin = PileBin(visible=2)
    >>> bin.reset(["a", "b", "c"], random.Random(0))
    >>> bin.look()
    ('a', 'c')
    >>> bin.take("c")
    >>> bin.look()
    ('a', 'b')
    """

    name = "pile"

    def reset(self, units, rng) -> None:
        super().reset(units, rng)
        self.rng.shuffle(self.units)

    def look(self) -> tuple[str, ...]:
        return tuple(self.units[: self.visible])

    def take(self, part: str) -> None:
        top = self.units[: self.visible]
        del self.units[top.index(part)]

    def shake(self) -> None:
        self.rng.shuffle(self.units)


class ConveyorBin(World):
    """Units pass a window of ``visible`` places in random order; the belt advances one place per
    look, and a unit not taken goes round again.  A shake is a wait for the belt.

    Parameters
    ----------
    visible : int, default 2
        Places in the window.

    Examples
    --------
    >>> import random
    >>> belt = ConveyorBin(visible=1)
    >>> belt.reset(["a", "b", "c"], random.Random(0))
    >>> belt.look(), belt.look()
    (('a',), ('c',))
    """

    name = "conveyor"

    def reset(self, units, rng) -> None:
        super().reset(units, rng)
        self.rng.shuffle(self.units)
        self._fresh = True

    def look(self) -> tuple[str, ...]:
        if not self._fresh and self.units:
            self.units.append(self.units.pop(0))  # the belt moves on: the first place goes round again
        self._fresh = False
        return tuple(self.units[: self.visible])

    def take(self, part: str) -> None:
        window = self.units[: self.visible]
        del self.units[window.index(part)]
        self._fresh = True  # the gap closes: the next look shows the window without moving


class PalletWorld(World):
    """Eliminated uncertainty: parts arrive on a pallet in the planned sequence.  The "look" is the
    next pallet location; no vision is needed.

    Parameters
    ----------
    sequence : sequence of str
        The planned sequence, one part id per unit.

    Examples
    --------
    >>> import random
    >>> pallet = PalletWorld(["a", "b"])
    >>> pallet.reset([], random.Random(0))
    >>> pallet.look()
    ('a',)
    """

    name = "pallet"

    def __init__(self, sequence: Sequence[str]):
        super().__init__(1)
        self.sequence = list(sequence)

    def reset(self, units, rng) -> None:
        super().reset(list(self.sequence), rng)

    def look(self) -> tuple[str, ...]:
        return tuple(self.units[:1])

    def take(self, part: str) -> None:
        """The unit at the pallet's next location leaves it.

        Parameters
        ----------
        part : str
            The part taken: the one the pallet presents.

        Raises
        ------
        RuntimeError
            If the pallet presents another part (a policy bug: a pallet offers no choice).

        Examples
        --------
        >>> import random
        >>> pallet = PalletWorld(["a", "b"])
        >>> pallet.reset([], random.Random(0))
        >>> pallet.take("b")
        Traceback (most recent call last):
            ...
        RuntimeError: the pallet presents ['a'], not 'b'
        """
        if not self.units or self.units[0] != part:
            raise RuntimeError(f"the pallet presents {self.units[:1]}, not '{part}'")
        self.units.pop(0)
