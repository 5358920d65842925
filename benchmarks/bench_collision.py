"""Which collision test decides blocking: opportune's separating-axis test against the libraries.

Each method answers the narrow-phase question of ``opportune derive`` on the same candidate pairs
(the bounding-box sweep of :func:`opportune.derive.blocking.find_blocking`): does convex body ``a``,
swept from far away along direction ``d`` into place, overlap convex body ``b`` by more than the
penetration tolerance?  The assemblies are the benchmark's random voxel blocks (one unit cube a body,
every part touching its neighbours face to face: sliding along those faces must not block), and the
part-level blocking relation each method gives is compared with the voxel brute force (the cells each
part sweeps on the grid).  Columns: pair tests, CPU seconds, and wrong blocking entries (part,
direction) out of all.  Each assembly is measured as built on the axes and turned by a random
rotation (directions turned with it: the same blocking relation, but the touching faces tilted, where
rounding decides between touching and overlapping).

* ``sat``: opportune's separating-axis test (exact on convex polyhedra; the least projected overlap is
  the penetration depth, compared with the tolerance).
* ``fcl``: python-fcl (FCL's GJK/EPA on ``Convex`` shapes: the swept body is the hull of the body and
  its copy moved out past the assembly); blocking when FCL reports a contact deeper than the tolerance.
* ``manifold``: manifold3d (the swept hull intersected with the other body by its exact boolean);
  blocking when the intersection's volume is over tolerance × its surface area / 2 (its mean thickness).
* ``mujoco``: MuJoCo's ``mj_geomDistance`` between mesh geoms (both bodies in one model); blocking
  when the signed distance is below minus the tolerance.

Usage: ``python benchmarks/bench_collision.py [--sizes 10,30] [--seed 0] [--markdown]``
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_derive import block_for, partition, write  # noqa: E402

from opportune.derive.blocking import AXES, candidate_pairs, depth  # noqa: E402
from opportune.derive.geometry import Body, read_assembly  # noqa: E402


def brute_blockers(parts: dict[str, list], block) -> dict[tuple[str, str], frozenset[str]]:
    """On the grid: the parts whose cells lie in the cells a part sweeps coming in along each axis."""
    owner = {c: p for p, cells in parts.items() for c in cells}
    out = {}
    for p, cells in parts.items():
        for name, d in AXES.items():
            hit = set()
            for c in cells:
                t = 1
                while True:
                    cell = tuple(int(c[i] - t * d[i]) for i in range(3))
                    if not all(0 <= cell[i] < block[i] for i in range(3)):
                        break
                    if owner.get(cell, p) != p:
                        hit.add(owner[cell])
                    t += 1
            out[p, name] = frozenset(hit)
    return out


def swept_points(body, d: np.ndarray, reach: float) -> np.ndarray:
    """The body's vertices and their copies moved ``reach`` back along ``d`` (the swept hull's points)."""
    return np.vstack([body.vertices, body.vertices - reach * d])


def method_sat(assembly, pairs, reach):
    return [depth(a, b, -d) > assembly.tolerance for a, b, d in pairs]


def method_fcl(assembly, pairs, reach):
    import fcl
    from scipy.spatial import ConvexHull

    def convex(points):
        hull = ConvexHull(points)
        faces = np.hstack([np.full((len(hull.simplices), 1), 3), hull.simplices]).ravel()
        return fcl.CollisionObject(fcl.Convex(points, len(hull.simplices), faces), fcl.Transform())

    request = fcl.CollisionRequest(enable_contact=True, num_max_contacts=1)
    out = []
    for a, b, d in pairs:
        result = fcl.CollisionResult()
        fcl.collide(convex(swept_points(a, d, reach)), convex(b.vertices), request, result)
        out.append(bool(result.is_collision and result.contacts
                        and result.contacts[0].penetration_depth > assembly.tolerance))
    return out


def method_manifold(assembly, pairs, reach):
    import manifold3d as m

    out = []
    for a, b, d in pairs:
        both = m.Manifold.hull_points(swept_points(a, d, reach)) ^ m.Manifold.hull_points(b.vertices)
        vol = both.volume()
        out.append(vol > 0 and 2 * vol / max(both.surface_area(), 1e-300) > assembly.tolerance)
    return out


def method_mujoco(assembly, pairs, reach):
    import mujoco

    out = []
    for a, b, d in pairs:
        pa, pb = swept_points(a, d, reach), b.vertices
        xml = ("<mujoco><asset>"
               f"<mesh name='a' vertex='{' '.join(map(str, pa.ravel()))}'/>"
               f"<mesh name='b' vertex='{' '.join(map(str, pb.ravel()))}'/>"
               "</asset><worldbody><geom type='mesh' mesh='a'/><geom type='mesh' mesh='b'/></worldbody></mujoco>")
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        out.append(mujoco.mj_geomDistance(model, data, 0, 1, 1.0, None) < -assembly.tolerance)
    return out


METHODS = {"sat": method_sat, "fcl": method_fcl, "manifold": method_manifold, "mujoco": method_mujoco}


def rotation(seed: int) -> np.ndarray:
    """A random rotation (seeded): the assembly turned off the axes, its touching faces tilted."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def measure(n: int, seed: int, methods, tilted: bool) -> list[tuple]:
    block = block_for(n)
    parts = partition(block, n, seed)
    truth = brute_blockers(parts, block)
    with tempfile.TemporaryDirectory() as tmp:
        write(Path(tmp), parts)
        assembly = read_assembly(tmp)
    units = {k: np.asarray(v, float) for k, v in AXES.items()}
    if tilted:      # the same assembly and directions turned: the same blocking relation
        turn = rotation(seed)
        assembly = replace(assembly, parts=tuple(
            replace(p, bodies=tuple(Body(b.vertices @ turn.T, b.normals @ turn.T, b.edges @ turn.T) for b in p.bodies))
            for p in assembly.parts))
        units = {k: turn @ v for k, v in units.items()}
    reach = 2 * assembly.size
    # the candidate body pairs of every (part, direction): what the narrow phase is asked
    jobs = []      # (part id, direction, other part id, body a, body b, d)
    for (i, dname, j, a, b) in candidate_pairs(assembly, units):
        jobs.append((assembly.parts[i].id, dname, assembly.parts[j].id, a, b, units[dname]))
    rows = []
    for name in methods:
        try:
            start = time.process_time()
            answers = METHODS[name](assembly, [(a, b, d) for *_, a, b, d in jobs], reach)
            seconds = time.process_time() - start
        except ImportError as exc:
            rows.append((n, tilted, name, len(jobs), None, f"not installed ({exc.name})"))
            continue
        found = {(p.id, d): set() for p in assembly.parts for d in AXES}
        for (p, dname, q, *_), hit in zip(jobs, answers):
            if hit:
                found[p, dname].add(q)
        wrong = sum(found[k] != truth[k] for k in truth)
        rows.append((n, tilted, name, len(jobs), seconds, f"{wrong} of {len(truth)}"))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,30")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table (docs/derive.md)")
    args = parser.parse_args()
    methods = args.methods.split(",")
    if args.markdown:
        print("| parts | pose | method | pair tests | CPU s | wrong blocking entries |\n|---:|---|---|---:|---:|---|")
    else:
        print(f"{'parts':>5} {'pose':>7} {'method':>9} {'pairs':>7} {'cpu_s':>8}  wrong")
    for n in (int(s) for s in args.sizes.split(",")):
        for tilted in (False, True):
            for n_, tilt, name, pairs, seconds, wrong in measure(n, args.seed, methods, tilted):
                secs = "–" if seconds is None else f"{seconds:.2f}"
                pose = "tilted" if tilt else "axes"
                if args.markdown:
                    print(f"| {n_} | {pose} | {name} | {pairs:,} | {secs} | {wrong} |")
                else:
                    print(f"{n_:>5} {pose:>7} {name:>9} {pairs:>7,} {secs:>8}  {wrong}", flush=True)


if __name__ == "__main__":
    main()
