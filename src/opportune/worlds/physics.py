"""A physical bin: the parts as rigid bodies heaped in a MuJoCo bin, seen by a camera through occlusion.

Each unit of the plan is a free rigid body whose shape and size come from its part's ``geometry``
(a box or a cylinder, in metres; :data:`DEFAULT_GEOMETRY` where the plan gives none), or its real
shape, ``convex`` bodies (as ``opportune derive`` writes them: each body a mesh geom, the convex hull
of its corners, all of them one rigid body centred on the part's bounding box).  A trial drops
them from seeded random poses into an open box and lets the heap settle; a camera above the bin's
centre casts a grid of :data:`RAY_GRID` × :data:`RAY_GRID` rays over each part's top (its footprint
seen from above):

* a part's *exposure* is the share of those rays that meet it (alone, :func:`mujoco.mju_rayGeom`)
  and hit it first (in the heap, :func:`mujoco.mj_multiRay`: one batch for every part);
* it is *visible* when its exposure is at least ``visible_fraction`` (default
  :data:`VISIBLE_FRACTION`, 30%);
* it is *pickable* when nothing lies on it: no contact with another part whose centre is higher,
  through a surface tilted less than about 78° from horizontal (contact normal ``|n_z| ≥``
  :data:`LYING_NORMAL_Z`).

A look reports the ``visible`` most exposed parts that are visible and pickable (the camera's
recognition picks the clearest; ties, such as parts in full view, in a random order drawn with the
heap and again at every shake).  A pick parks the body far from the bin
(collisions off, gravity compensated) and lets the heap settle; a shake gives every part in the bin
one seeded random velocity (the bin's jerk, the same for all) plus a small random velocity and spin of
its own, and lets it settle.  Settling runs up to ``settle_steps`` steps of :data:`TIMESTEP` seconds,
and stops early once no part moves faster than :data:`SETTLED_SPEED`.

Everything random comes from the ``random.Random`` of :meth:`PhysicsBin.reset`: the same seed gives
the same heap, looks and trial on one machine (MuJoCo is deterministic single-threaded; another CPU
or MuJoCo version may round differently).  The settled first heap of a seed is kept
(:data:`HEAP_CACHE` heaps per process), so the strategies of a study, which see the same bins, drop
each one once.

Bounds, checked before any model is built (:class:`PhysicsError`, a ``ValueError``, says what to
change): at most :data:`MAX_BIN_UNITS` units; every dimension within ``plan.MIN_DIMENSION`` ..
``plan.MAX_DIMENSION``; every part's footprint within the bin; the parts' volume at most
:data:`MAX_FILL` of the bin's; bin sides within :data:`MIN_BIN` .. :data:`MAX_BIN`; settle steps
within :data:`MIN_SETTLE_STEPS` .. :data:`MAX_SETTLE_STEPS`.  A look costs O(units × rays) ray-geom
tests; a settle at most ``settle_steps`` MuJoCo steps, each about O(units + contacts).

>>> import random
>>> from opportune.worlds.physics import PhysicsBin
>>> world = PhysicsBin(visible=2)
>>> world.reset(["a", "b", "c", "d"], random.Random(1))
>>> look = world.look(); len(look) <= 2 and set(look) <= {"a", "b", "c", "d"}
True
"""

from __future__ import annotations

import math
import random
from collections import OrderedDict
from typing import Mapping, Sequence

from opportune.planning.plan import MAX_DIMENSION, MIN_DIMENSION, SHAPES
from opportune.worlds.bins import World

#: The shape of a part whose plan gives no ``geometry``: a box of 40 × 30 × 20 mm.
DEFAULT_GEOMETRY = ("box", (0.04, 0.03, 0.02))
#: The bin's inside by default: length, width and wall height, metres.
DEFAULT_BIN = (0.16, 0.12, 0.10)
MIN_BIN, MAX_BIN = 0.05, 2.0
MAX_BIN_UNITS = 100            # bodies in one bin (contacts and steps grow with them)
MAX_FILL = 0.35                # the parts' volume, as a share of the bin's inside at most
DEFAULT_SETTLE_STEPS = 400     # 1.6 s of simulated time: a heap of ten parts settles in 0.4-1.3 s
MIN_SETTLE_STEPS, MAX_SETTLE_STEPS = 10, 20_000
TIMESTEP = 0.004               # seconds per step
SETTLED_SPEED = 0.02           # m/s (and rad/s): a heap whose parts all move slower has settled
CHECK_EVERY = 20               # steps between two checks of that
VISIBLE_FRACTION = 0.3         # share of a part's top the camera must see
RAY_GRID = 6                   # rays per side of the grid over a part's top (36 rays)
CAMERA_ABOVE = 0.4             # metres from the top of the walls to the camera
LYING_NORMAL_Z = 0.2           # contacts steeper than this (|n_z| < 0.2) are side by side, not on top
SHAKE_SPEED = 0.35             # m/s: the bin's jerk, horizontal, in a random direction
SHAKE_LIFT = 0.4               # m/s upwards
SHAKE_JITTER = 0.15            # m/s, each part's own random velocity on top of the jerk
SHAKE_SPIN = 6.0               # rad/s, each part's random spin at most
HEAP_CACHE = 256               # settled first heaps kept per process
_WALL = 0.01                   # wall thickness, metres
_PARKED = 50.0                 # metres from the bin where picked parts wait
_DENSITY = 2700                # kg/m³ (aluminium)


class PhysicsError(ValueError):
    """A physical bin that cannot be built as asked (too many parts, a part larger than the bin...)."""


def require_mujoco():
    """The mujoco module, or :class:`PhysicsError` saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise PhysicsError("the physical bin needs MuJoCo: pip install 'opportune[physics]'") from None
    return mujoco


def _volume(geometry: tuple) -> float:
    """The part's volume (a convex shape's: its bodies' bounding boxes, at least the true volume)."""
    shape, dims = geometry
    if shape == "convex":
        return sum(math.prod(max(p[a] for p in b) - min(p[a] for p in b) for a in range(3)) for b in dims)
    return dims[0] * dims[1] * dims[2] if shape == "box" else math.pi * dims[0] ** 2 * dims[1]


def _centre(bodies) -> tuple[float, float, float]:
    """The centre of a convex shape's bounding box: the origin of its rigid body."""
    return tuple((min(p[a] for b in bodies for p in b) + max(p[a] for b in bodies for p in b)) / 2 for a in range(3))


def _radius(geometry: tuple) -> float:
    """Half the diagonal of the part: the radius of a sphere holding it."""
    shape, dims = geometry
    if shape == "box":
        return 0.5 * math.sqrt(sum(d * d for d in dims))
    if shape == "convex":
        c = _centre(dims)
        return max(math.dist(p, c) for b in dims for p in b)
    return math.sqrt(dims[0] ** 2 + (dims[1] / 2) ** 2)


def _extent(geometry: tuple) -> list[float]:
    """A part's three sides (a convex shape's bounding box; a cylinder's diameter, diameter, height)."""
    shape, dims = geometry
    if shape == "convex":
        return [max(p[a] for b in dims for p in b) - min(p[a] for b in dims for p in b) for a in range(3)]
    return list(dims) if shape == "box" else [2 * dims[0], 2 * dims[0], dims[1]]


def _shape_problem(part: str, geometry: tuple) -> str | None:
    """What is wrong with a part's geometry for the bin, or None (the plan's own bounds, for a geometry
    given in Python rather than read from a plan)."""
    shape, dims = geometry
    if shape == "convex":
        from opportune.formats.shapes import COORDINATE, THICKNESS, thickness
        from opportune.limits import MAX_BODY_POINTS, MAX_SHAPE_BODIES

        ok = (1 <= len(dims) <= MAX_SHAPE_BODIES and all(4 <= len(b) <= MAX_BODY_POINTS for b in dims)
              and all(len(p) == 3 and all(math.isfinite(c) and abs(c) <= COORDINATE for c in p) for b in dims for p in b))
        if not ok:
            return (f"part '{part}': a convex shape is 1 to {MAX_SHAPE_BODIES} bodies of 4 to {MAX_BODY_POINTS} corners "
                    f"(x, y, z), each coordinate within {COORDINATE:g} m")
        side = max(_extent(geometry))
        if not MIN_DIMENSION <= side <= MAX_DIMENSION or any(thickness(b) < THICKNESS for b in dims):
            return (f"part '{part}': its shape must be {MIN_DIMENSION:g} to {MAX_DIMENSION:g} m along its longest side, "
                    f"each body at least {THICKNESS:g} m thick")
        return None
    if shape not in SHAPES or len(dims) != SHAPES[shape] or not all(MIN_DIMENSION <= d <= MAX_DIMENSION for d in dims):
        return (f"part '{part}': geometry {shape} {list(dims)} is not a box of 3 or a cylinder of 2 "
                f"dimensions from {MIN_DIMENSION:g} to {MAX_DIMENSION:g} m")
    return None


def check_bin(units: Sequence[str], geometry: Mapping[str, tuple], bin_size: Sequence[float],
              settle_steps: int, visible_fraction: float) -> None:
    """Raise :class:`PhysicsError` unless a bin of ``bin_size`` can hold ``units`` of these shapes.
    O(units); nothing is built."""
    if len(bin_size) != 3 or not all(MIN_BIN <= float(s) <= MAX_BIN for s in bin_size):
        raise PhysicsError(f"the bin's inside is length, width and wall height, each from {MIN_BIN:g} to "
                           f"{MAX_BIN:g} m, not {list(bin_size)}: fix simulation.physics.bin")
    if not (isinstance(settle_steps, int) and MIN_SETTLE_STEPS <= settle_steps <= MAX_SETTLE_STEPS):
        raise PhysicsError(f"settle_steps must be a whole number from {MIN_SETTLE_STEPS} to {MAX_SETTLE_STEPS:,}, "
                           f"not {settle_steps!r}: fix simulation.physics.settle_steps")
    if not 0 < visible_fraction <= 1:
        raise PhysicsError(f"visible_fraction must be above 0 and at most 1, not {visible_fraction!r}")
    if len(units) > MAX_BIN_UNITS:
        raise PhysicsError(f"the physical bin holds at most {MAX_BIN_UNITS} parts, and the plan has {len(units):,} "
                           "units: use another --bin (uniform, weighted, pile or conveyor)")
    length, width, height = (float(s) for s in bin_size)
    volume = 0.0
    for part in dict.fromkeys(units):
        shape, dims = geometry.get(part, DEFAULT_GEOMETRY)
        problem = _shape_problem(part, (shape, dims))
        if problem:
            raise PhysicsError(problem)
        # lying on its largest face (a cylinder on its side), its footprint must fit the bin's floor
        footprint = sorted(dims)[1:] if shape == "box" else sorted((2 * dims[0], dims[1])) if shape == "cylinder" \
            else sorted(_extent((shape, dims)))[1:]
        if footprint[1] > max(length, width) or footprint[0] > min(length, width):
            sides = list(dims) if shape != "convex" else [round(e, 4) for e in _extent((shape, dims))]
            raise PhysicsError(f"part '{part}' ({shape} {sides} m) cannot lie flat in a bin {length:g} × {width:g} m: "
                               "make the bin larger (simulation.physics.bin) or check the part's geometry")
    for part in units:
        volume += _volume(geometry.get(part, DEFAULT_GEOMETRY))
    if volume > MAX_FILL * length * width * height:
        raise PhysicsError(f"the parts' volume, {1e6 * volume:,.0f} cm³, is more than {100 * MAX_FILL:g}% of the bin's "
                           f"({1e6 * length * width * height:,.0f} cm³): make the bin larger (simulation.physics.bin)")


def _model_xml(units: Sequence[str], geometry: Mapping[str, tuple], bin_size: Sequence[float]) -> str:
    length, width, height = bin_size
    hx, hy, t = length / 2, width / 2, _WALL
    walls = [(0, hy + t, 2 * t + hx, t), (0, -hy - t, 2 * t + hx, t), (hx + t, 0, t, hy), (-hx - t, 0, t, hy)]
    xml = ['<mujoco><option timestep="%g" integrator="implicitfast" iterations="30" ls_iterations="10" tolerance="1e-6"/>' % TIMESTEP,
           '<default><geom friction="0.7 0.005 0.0001" solref="0.008 1" condim="3"/></default><worldbody>',
           '<geom name="floor" type="plane" size="0 0 1"/>']
    for i, (x, y, sx, sy) in enumerate(walls):
        xml.append(f'<geom name="wall{i}" type="box" pos="{x:g} {y:g} {height / 2:g}" size="{sx:g} {sy:g} {height / 2:g}"/>')
    meshes: list[str] = []
    kinds = {part: k for k, part in enumerate(dict.fromkeys(units))}
    for part, k in kinds.items():
        shape, dims = geometry.get(part, DEFAULT_GEOMETRY)
        if shape == "convex":   # the corners about the part's centre: the rigid body's origin
            c = _centre(dims)
            meshes += [f'<mesh name="m{k}_{b}" vertex="' + " ".join(f"{p[a] - c[a]:.9g}" for p in body for a in range(3))
                       + '"/>' for b, body in enumerate(dims)]
    for i, part in enumerate(units):
        shape, dims = geometry.get(part, DEFAULT_GEOMETRY)
        xml.append(f'<body name="u{i}" pos="{_PARKED + i:g} 0 1"><freejoint/>')
        if shape == "convex":
            xml += [f'<geom name="g{i}{"" if b == 0 else f"_{b}"}" type="mesh" mesh="m{kinds[part]}_{b}" '
                    f'density="{_DENSITY}"/>' for b in range(len(dims))]
        else:
            size = " ".join(f"{d / 2:g}" for d in dims) if shape == "box" else f"{dims[0]:g} {dims[1] / 2:g}"
            xml.append(f'<geom name="g{i}" type="{shape}" size="{size}" density="{_DENSITY}"/>')
        xml.append("</body>")
    xml.append("</worldbody>")
    if meshes:
        xml.append("<asset>" + "".join(meshes) + "</asset>")
    xml.append("</mujoco>")
    return "".join(xml)


def _plain_geometry(geometry) -> tuple:
    """A geometry as tuples of floats (hashable: the heaps' cache keys hold it)."""
    shape, dims = geometry
    if shape == "convex":
        return (shape, tuple(tuple(tuple(float(c) for c in p) for p in b) for b in dims))
    return (shape, tuple(float(d) for d in dims))


_HEAPS: OrderedDict = OrderedDict()


class PhysicsBin(World):
    """A bin of rigid parts in MuJoCo; see the module for what is seen, what can be picked, and the bounds.

    Unit ``i`` of the trial (the ``i``-th of the ``units`` given to :meth:`reset`) is the body ``u{i}``
    with the geom ``g{i}`` of :attr:`model`; :attr:`data` holds the heap's state.

    ``geometry`` maps part ids to ``(shape, dimensions)`` (a plan's ``Part.geometry``); ``bin_size`` is the
    bin's inside (length, width, wall height) in metres.
    """

    name = "physics"

    def __init__(self, visible: int = 2, geometry: Mapping[str, tuple] | None = None, *,
                 bin_size: Sequence[float] = DEFAULT_BIN, settle_steps: int = DEFAULT_SETTLE_STEPS,
                 visible_fraction: float = VISIBLE_FRACTION):
        super().__init__(visible)
        self.geometry = {k: _plain_geometry(v) for k, v in dict(geometry or {}).items()}
        self.bin_size = tuple(float(s) for s in bin_size)
        self.settle_steps = settle_steps
        self.visible_fraction = float(visible_fraction)
        check_bin([], self.geometry, self.bin_size, settle_steps, self.visible_fraction)
        self.model = self.data = None
        self._built_for: tuple | None = None
        self.alive: list[int] = []       # body index (unit number) of each unit in the bin, as self.units
        self._look: tuple | None = None  # (units of the last look, its part ids) until the heap moves

    # ------------------------------------------------------------ building and resetting

    def _build(self, units: Sequence[str]) -> None:
        mujoco = require_mujoco()
        check_bin(units, self.geometry, self.bin_size, self.settle_steps, self.visible_fraction)
        try:
            self.model = mujoco.MjModel.from_xml_string(_model_xml(units, self.geometry, self.bin_size))
        except ValueError as exc:   # MuJoCo's compiler refuses a shape (a hull it cannot make): say so
            raise PhysicsError(f"MuJoCo cannot build the bin from these shapes ({str(exc)[:300]}): check the parts' "
                               "geometry") from None
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._geom = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"g{i}") for i in range(len(units))]
        self._body = [int(m.geom_bodyid[g]) for g in self._geom]
        # every geom of each unit (a convex shape has one a body), and whether the unit is a primitive
        self._geoms = [[g for g in range(m.ngeom) if int(m.geom_bodyid[g]) == b] for b in self._body]
        self._mesh = [int(m.geom_type[g]) == mujoco.mjtGeom.mjGEOM_MESH for g in self._geom]
        self._qadr = [int(m.jnt_qposadr[m.body_jntadr[b]]) for b in self._body]
        self._vadr = [int(m.jnt_dofadr[m.body_jntadr[b]]) for b in self._body]
        self._unit_of_geom = {g: i for i, gs in enumerate(self._geoms) for g in gs}
        self._built_for = tuple(units)

    def reset(self, units: Sequence[str], rng: random.Random) -> None:
        """Drop ``units`` into the empty bin from random poses drawn from ``rng``, and let them settle."""
        super().reset(units, rng)
        if self._built_for != tuple(units):
            self._build(units)
        mujoco = require_mujoco()
        m, d = self.model, self.data
        seed = rng.getrandbits(64)   # one draw, whether the heap is cached or not: the stream stays the same
        key = (self._built_for, tuple(sorted(self.geometry.items())), self.bin_size, self.settle_steps, seed)
        self.alive = list(range(len(units)))
        for i in self.alive:
            self._enable(i, True)
        # ties of exposure (parts in full view) go to a random order of the units, drawn with the heap
        ties = random.Random(seed + 1)
        self._tie = [ties.random() for _ in units]
        cached = _HEAPS.get(key)
        if cached is not None:
            _HEAPS.move_to_end(key)
        else:
            mujoco.mj_resetData(m, d)   # nothing of the last trial (velocities, warm start) in this drop
            self._drop(random.Random(seed))
            self._settle()
            cached = _HEAPS[key] = d.qpos.copy()
            if len(_HEAPS) > HEAP_CACHE:
                _HEAPS.popitem(last=False)
        # Dropped now or before, the trial starts from the settled poses alone (at rest, no solver warm
        # start): the same state whichever worker dropped the heap, so trials do not depend on the cache.
        mujoco.mj_resetData(m, d)
        d.qpos[:] = cached
        mujoco.mj_forward(m, d)
        self._look = None

    def _drop(self, rng: random.Random) -> None:
        """Random poses one above the other (no two overlap), in a random order, at random places."""
        d = self.data
        length, width, height = self.bin_size
        order = list(self.alive)
        rng.shuffle(order)
        z = 0.0
        for i in order:
            r = _radius(self.geometry.get(self._built_for[i], DEFAULT_GEOMETRY))
            x = (rng.random() - 0.5) * max(0.0, length - 2 * r)
            y = (rng.random() - 0.5) * max(0.0, width - 2 * r)
            z += r
            q = [rng.gauss(0, 1) for _ in range(4)]
            norm = math.sqrt(sum(c * c for c in q)) or 1.0
            a = self._qadr[i]
            d.qpos[a:a + 7] = [x, y, z + 0.002, *(c / norm for c in q)]
            z += r + 0.002
        require_mujoco().mj_forward(self.model, d)

    def _enable(self, i: int, on: bool) -> None:
        m = self.model
        for g in self._geoms[i]:
            m.geom_contype[g] = m.geom_conaffinity[g] = 1 if on else 0
        m.body_gravcomp[self._body[i]] = 0.0 if on else 1.0

    def _settle(self) -> int:
        """Step until no part in the bin moves faster than :data:`SETTLED_SPEED`, at most ``settle_steps``
        steps; the steps taken."""
        mujoco = require_mujoco()
        m, d = self.model, self.data
        dofs = [a + k for i in self.alive for a in (self._vadr[i],) for k in range(6)]
        steps = 0
        while steps < self.settle_steps:
            n = min(CHECK_EVERY, self.settle_steps - steps)
            mujoco.mj_step(m, d, nstep=n)
            steps += n
            if not dofs or float(abs(d.qvel[dofs]).max()) < SETTLED_SPEED:
                break
        mujoco.mj_forward(m, d)   # contacts and poses of the settled heap, for looks
        return steps

    # ------------------------------------------------------------ what the camera sees

    @property
    def camera(self) -> tuple[float, float, float]:
        """The camera's position: above the bin's centre."""
        return (0.0, 0.0, self.bin_size[2] + CAMERA_ABOVE)

    def rays(self, unit: int):
        """The directions (from :attr:`camera`) of the rays over ``unit``'s top: a grid over its footprint
        seen from above (its bounding rectangle in x and y), aimed at the height of its centre; an array
        of shape (RAY_GRID², 3)."""
        import numpy as np

        g = self._geom[unit]
        pos = self.data.geom_xpos[g]
        mat = self.data.geom_xmat[g].reshape(3, 3)
        size = self.model.geom_size[g]
        if self._mesh[unit]:
            pos, extent = self._box_of(unit)
        elif self.model.geom_type[g] == require_mujoco().mjtGeom.mjGEOM_BOX:
            extent = np.abs(mat[:2, :]) @ size
        else:   # a cylinder: its axis is the frame's z
            axis = mat[:2, 2]
            extent = np.abs(axis) * size[1] + size[0] * np.sqrt(np.maximum(0.0, 1 - axis ** 2))
        steps = (np.arange(RAY_GRID) + 0.5) / RAY_GRID * 2 - 1
        gx, gy = np.meshgrid(pos[0] + steps * extent[0], pos[1] + steps * extent[1], indexing="ij")
        targets = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, pos[2])], axis=1)
        return targets - np.array(self.camera)

    def _box_of(self, unit: int):
        """A convex unit's bounding box in the world: its centre and half sides (each geom's box, turned)."""
        import numpy as np

        d, m = self.data, self.model
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for g in self._geoms[unit]:
            mat = d.geom_xmat[g].reshape(3, 3)
            centre = d.geom_xpos[g] + mat @ m.geom_aabb[g, :3]
            half = np.abs(mat) @ m.geom_aabb[g, 3:]
            lo, hi = np.minimum(lo, centre - half), np.maximum(hi, centre + half)
        return (lo + hi) / 2, (hi - lo) / 2

    def _meets(self, unit: int, vec) -> list[bool]:
        """For each ray, whether it meets ``unit``'s part alone (nothing else in the way)."""
        import numpy as np

        mujoco = require_mujoco()
        g = self._geom[unit]
        d, m = self.data, self.model
        pnt = np.array(self.camera)
        if self._mesh[unit]:
            return [any(mujoco.mj_rayMesh(m, d, h, pnt, v.copy()) >= 0 for h in self._geoms[unit]) for v in vec]
        return [mujoco.mju_rayGeom(d.geom_xpos[g], d.geom_xmat[g], m.geom_size[g], pnt, v.copy(),
                                   int(m.geom_type[g])) >= 0 for v in vec]

    def exposure(self) -> dict[int, float]:
        """Each unit in the bin's share of rays over its top that hit it first: one batch of rays
        (:func:`mujoco.mj_multiRay`) for all of them.  O(units × rays × geoms)."""
        import numpy as np

        mujoco = require_mujoco()
        vecs = [self.rays(i) for i in self.alive]
        if not vecs:
            return {}
        vec = np.ascontiguousarray(np.concatenate(vecs))
        n = len(vec)
        geomid = np.zeros(n, dtype=np.int32)
        dist = np.zeros(n)
        mujoco.mj_multiRay(self.model, self.data, np.array(self.camera), vec.ravel(), None, 1, -1, geomid, dist,
                           None, n, 1e3)
        out = {}
        for k, i in enumerate(self.alive):
            meets = self._meets(i, vecs[k])
            first = np.isin(geomid[k * RAY_GRID ** 2:(k + 1) * RAY_GRID ** 2], self._geoms[i])
            seen = sum(1 for a, b in zip(meets, first) if a and b)
            out[i] = seen / max(1, sum(meets))
        return out

    def covered(self) -> set[int]:
        """The units in the bin that another part lies on (see the module): not pickable.  O(contacts)."""
        d = self.data
        unit_of = self._unit_of_geom
        out = set()
        for k in range(d.ncon):
            c = d.contact[k]
            a, b = unit_of.get(int(c.geom1)), unit_of.get(int(c.geom2))
            if a is None or b is None or abs(float(c.frame[2])) < LYING_NORMAL_Z:
                continue
            za, zb = self._height(a), self._height(b)
            if abs(za - zb) > 1e-3:
                out.add(a if za < zb else b)
        return out

    def _height(self, unit: int) -> float:
        """The height of a unit's centre (a primitive's geom, a convex shape's body origin)."""
        if self._mesh[unit]:
            return float(self.data.xpos[self._body[unit]][2])
        return float(self.data.geom_xpos[self._geom[unit]][2])

    def look(self) -> tuple[str, ...]:
        """The ``visible`` most exposed parts that are visible and pickable (fewer if fewer are)."""
        if self._look is None:
            exposure = self.exposure()
            covered = self.covered()
            ok = [i for i in self.alive if exposure[i] >= self.visible_fraction and i not in covered]
            ok.sort(key=lambda i: (-exposure[i], self._tie[i]))
            seen = ok[:self.visible]
            self._look = (seen, tuple(self._built_for[i] for i in seen))
        return self._look[1]

    # ------------------------------------------------------------ acting on the bin

    def take(self, part: str) -> None:
        """The most exposed unit of ``part`` in the last look leaves the bin; the heap settles."""
        seen = self._look[0] if self._look else []
        unit = next((i for i in seen if self._built_for[i] == part), None)
        if unit is None:
            raise ValueError(f"'{part}' was not in the last look of the physical bin ({', '.join(self.look())})")
        mujoco = require_mujoco()
        d = self.data
        a, v = self._qadr[unit], self._vadr[unit]
        d.qpos[a:a + 7] = [_PARKED + unit, 0, 1, 1, 0, 0, 0]
        d.qvel[v:v + 6] = 0
        self._enable(unit, False)
        k = self.alive.index(unit)
        del self.alive[k]
        del self.units[k]
        mujoco.mj_forward(self.model, d)
        self._settle()
        self._look = None

    def shake(self) -> None:
        """Jerk the bin: every part gets the same random horizontal velocity and lift, plus its own random
        velocity and spin (all from the trial's random stream); the heap settles."""
        rng = self.rng
        d = self.data
        angle = rng.random() * 2 * math.pi
        jerk = (SHAKE_SPEED * math.cos(angle), SHAKE_SPEED * math.sin(angle), SHAKE_LIFT)
        for i in self.alive:
            v = self._vadr[i]
            d.qvel[v:v + 3] = [j + (rng.random() * 2 - 1) * SHAKE_JITTER for j in jerk]
            d.qvel[v + 3:v + 6] = [(rng.random() * 2 - 1) * SHAKE_SPIN for _ in range(3)]
        self._tie = [rng.random() for _ in self._tie]   # the camera sees the shaken heap afresh
        self._settle()
        self._look = None

    def place(self, poses: Mapping[int, Sequence[float]]) -> None:
        """Put units at chosen poses ``(x, y, z, qw, qx, qy, qz)`` (metres, a unit quaternion) and let the
        heap settle: a heap built on purpose, for tests and demonstrations.  Units not named stay put."""
        d = self.data
        for unit, pose in poses.items():
            if unit not in self.alive or len(pose) != 7:
                raise ValueError(f"unit {unit}: give a unit in the bin and a pose of 7 numbers")
            a, v = self._qadr[unit], self._vadr[unit]
            d.qpos[a:a + 7] = pose
            d.qvel[v:v + 6] = 0
        require_mujoco().mj_forward(self.model, d)
        self._settle()
        self._look = None

    def units_in_bin(self) -> list[int]:
        """The unit numbers (bodies) still in the bin, in the order of :attr:`units`."""
        return list(self.alive)

    def geom_of(self, unit: int) -> int:
        """The MuJoCo geom id of a unit."""
        return self._geom[unit]

