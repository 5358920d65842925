"""Where plans come from, on the command line: ``derive`` (from the product's geometry), ``learn`` (from
observed sequences) and ``relax`` (an over-constrained plan made admissible).

The work is in :mod:`opportune.derive`; what is here is option plumbing, the plan written as YAML that
reads like a hand-written one, and the report on standard error.

Imports: typer only; each command loads its own machinery when it runs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

from opportune.cli.common import (PLAN_ARG, err, escape, fail, fail_problem, json_invalid_plan, json_option,
                                  print_problems, write_text)


def derive(
    assembly: Path = typer.Argument(..., help="The product in its assembled pose: a folder of meshes, one file a part "
                                              "(.obj, .stl, .ply; the part id is the file's stem), a glTF/GLB scene "
                                              "(named nodes), a MuJoCo MJCF model (named bodies) or a STEP file "
                                              "(products; the step extra)",
                                    show_default=False),
    manifest: Optional[Path] = typer.Option(None, "--manifest", help="The assembly's manifest (YAML: names, "
                                                                     "quantities, base, fixture, directions, "
                                                                     "requires); default: assembly.yaml in the folder"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Write the plan (YAML) here instead of "
                                                                       "standard output"),
    directions: Optional[str] = typer.Option(None, "--directions", help="Insertion directions: axes (the six "
                                             "axis directions), or a list such as \"+z,-x,0 0.7 0.7\" (default: the "
                                             "manifest's, else the axes and the normals of the contacts between parts)"),
    gravity: Optional[str] = typer.Option(None, "--gravity", help="Gravity's direction (e.g. -z): each part after "
                                          "the first rests on a part below it that it touches, or on the fixture"),
    connected: bool = typer.Option(False, "--connected", help="Each part after the first touches a part already in"),
    base: Optional[str] = typer.Option(None, "--base", help="The part that goes first"),
    tolerance: Optional[float] = typer.Option(None, "--tolerance", min=0.0,
                                              help="Penetration tolerance in the files' units: parts may overlap by "
                                                   "this much (default: a millionth of the assembly's size)"),
    units: str = typer.Option("m", "--units", help="The files' unit of length: m or mm"),
    explain: bool = typer.Option(False, "--explain", help="Print why the plan is as it is instead of the plan: each "
                                                          "forced order with the part in the way, the parts with one "
                                                          "insertion direction, the count, and what would free the most"),
    figure: Optional[Path] = typer.Option(None, "--figure", help="Draw the exploded view (.png, .svg or .pdf): each "
                                                                 "part moved out along its insertion direction, coloured "
                                                                 "by stage"),
    strategy: int = typer.Option(1, "--strategy", min=1, help="The strategy the figure explodes (from 1)"),
    as_json: bool = json_option("Machine-readable output: {\"parts\", \"directions\", \"blocking_checks\", "
                                "\"strategies\", \"blockers\", ...} on standard output (errors too)"),
):
    """Derive the plan of an assembly from its parts' shapes: exactly the sequences in which each part can go in
    by one straight translation along one of the directions, never through another part.

    Refuses (exit 1) an unusable mesh (naming the part), an assembly with no feasible sequence (naming the parts
    that lock each other) and one whose exact plan needs more strategies than a plan holds.
    """
    try:
        from opportune.derive import DeriveError, GeometryError, ManifestError
        from opportune.derive import derive as derive_plan
    except ImportError as exc:   # trimesh missing: the geometry extra
        fail(f"opportune derive needs the geometry extra: pip install 'opportune[geometry]' ({exc})")
    try:
        derived = derive_plan(assembly, directions=directions, tolerance=tolerance, units=units, gravity=gravity,
                              connected=connected, base=base, manifest=manifest)
    except (GeometryError, DeriveError, ManifestError) as exc:
        fail(str(exc))
    from opportune.derive.show import show

    try:   # before the plan is written: a figure that cannot be drawn leaves no plan file behind
        shown = show(derived, explain=explain, figure=figure, strategy=strategy)
    except (ValueError, OSError) as exc:
        fail(str(exc))
    text = _plan_yaml(derived.plan.to_dict())
    if output is not None:
        write_text(output, text)
    if as_json:
        print(json.dumps({"plan": derived.plan.to_dict(), **derived.to_dict(), **shown.data}, indent=2,
                         ensure_ascii=False))
        return
    if explain:
        sys.stdout.write(shown.text)
    elif output is None:
        sys.stdout.write(text)
    for note in shown.notes:
        err().print(f"[yellow]note[/]: {escape(note)}", markup=True)
    d = derived.to_dict()
    err().print(escape(f"{derived.plan.name}: {d['parts']} parts, {len(d['directions'])} directions, "
                         f"{d['blocking_checks']:,} blocking checks, {d['strategies']} strateg"
                         f"{'y' if d['strategies'] == 1 else 'ies'}, {d['constraints']} constraints, "
                         f"{d['cpu_seconds']:.2f} s CPU" + (f"; wrote {output}" if output is not None else "")))


def learn(
    sequences: str = typer.Argument(..., help="Successful sequences: one per line, part ids separated by spaces or "
                                              "commas, # comments; - for standard input; example:NAME for a shipped "
                                              "one (example:gearbox-observed)", show_default=False),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="Write the plan (YAML) to this file instead "
                                                                       "of standard output"),
    failed: Optional[str] = typer.Option(None, "--failed", help="Failed sequences (same format and parts): report "
                                                                "the constraints each breaks, and those none can "
                                                                "exclude"),
    name: Optional[str] = typer.Option(None, "--name", help="The plan's name (default: the file's stem)"),
    max_accident: float = typer.Option(0.05, "--max-accident", min=0.0, max=1.0,
                                       help="Flag (in the comments, the JSON and on standard error) the constraints "
                                            "whose accident probability is above this; they stay in the plan"),
    split: bool = typer.Option(False, "--split", help="When failed sequences cannot be excluded by one partial "
                                                      "order, write the two-strategy repair (if found) instead"),
    time_limit: float = typer.Option(20.0, "--time-limit", min=0.1, max=3600.0,
                                     help="Seconds for all the exact counts behind the accident probabilities "
                                          "(those over it are reported as not computed)"),
    as_json: bool = json_option("Machine-readable output: {\"plan\", \"constraints\", \"sequences\", \"failed\", "
                                "\"unexcluded\", \"repair\", ...} on standard output (errors too)"),
):
    """Learn a plan from observed successful sequences: the constraints every sequence satisfies (minimal set),
    each with its support and the probability that it is an accident of too few observations."""
    from opportune.formats.sequences import SequenceError, read_sequences
    from opportune.derive.learn import learn_plan
    from opportune.planning.plan import PlanError

    if name is not None and not name.strip():
        fail("--name: give a non-empty name", 2)
    if failed == "-" and sequences == "-":
        fail("only one of SEQUENCES and --failed can be standard input (-)", 2)
    try:
        good = read_sequences(sequences)
        bad = read_sequences(failed, like=good, what="failed sequences") if failed else ()
        stem = sequences.split(":", 1)[1] if sequences.lower().startswith("example:") else Path(sequences).stem
        learned = learn_plan(good, bad, name=name or (stem if sequences != "-" and stem else "learned"),
                             max_accident=max_accident, time_limit=time_limit)
    except SequenceError as exc:
        fail_problem(exc.problem)
    except PlanError as exc:    # the learned plan is built through the plan checker: say what it found
        fail(f"the learned plan is not valid: {exc}")
    text = learned.to_yaml(repaired=split)
    if output is not None:
        write_text(output, text)
    if as_json:
        doc = learned.to_json()
        if split and learned.repair is not None:
            doc["written"] = "repair"
        print(json.dumps(doc, indent=2, ensure_ascii=False))
    elif output is None:
        sys.stdout.write(text)
    _report_learned(learned, output, max_accident, time_limit, split)

def _report_learned(learned, output: Optional[Path], max_accident: float, time_limit: float, split: bool) -> None:
    """``learn``'s report on standard error: what was learnt, the constraints that may be accidents, and
    the failed sequences each constraint excludes or none can."""
    say = err()
    n = len(learned.constraints)
    say.print(f"learned {n} constraint{'s' if n != 1 else ''} from {learned.sequences} sequence"
              f"{'s' if learned.sequences != 1 else ''} ({learned.distinct} different)"
              + (f"; wrote {escape(str(output))}" if output is not None else ""))
    if learned.flagged:
        shown = ", ".join(f"{c.before} -> {c.after} ({c.accident_probability:.2g})" for c in learned.flagged[:20])
        more = f", … ({len(learned.flagged) - 20} more)" if len(learned.flagged) > 20 else ""
        say.print(f"[yellow]warning[/]: {len(learned.flagged)} constraint(s) may be accidents of too few observations "
                  f"(accident probability above {max_accident:g}): {escape(shown + more)} — kept in the plan; more "
                  "observations would settle them", markup=True)
    if not learned.complete:
        say.print("[yellow]warning[/]: some accident probabilities were not computed within --time-limit "
                  f"{time_limit:g} s (marked 'not computed')", markup=True)
    for f in learned.failed:
        if f.excluded:
            broken = ", ".join(f"{b} -> {a}" for b, a in f.violates)
            say.print(f"{escape(f.where)}: failed sequence breaks {escape(broken)} (confirmed)")
    for f in learned.unexcluded:
        why = ("the same sequence is also among the successes" if f.succeeded else
               "it satisfies every learned constraint, so no single partial order that admits all the successes "
               "excludes it")
        say.print(f"[yellow]warning[/]: {escape(f.where)}: failed sequence cannot be excluded: {escape(why)}",
                  markup=True)
    if learned.unexcluded:
        hint = "" if split or learned.repair is None else " (--split writes it)"
        say.print(f"  repair: {escape(learned.repair_note)}{hint}")


def relax(
    plan_file: Path = PLAN_ARG,
    output: Optional[Path] = typer.Option(None, "-o", "--output",
                                          help="Write the relaxed plan (YAML) here instead of standard output"),
    installed: Optional[str] = typer.Option(None, "--installed",
                                            help='Parts already installed, in order ("ca ba" or "ca,ba"): the '
                                                 "relaxed plan admits this prefix"),
    time_limit: float = typer.Option(10.0, "--time-limit", min=0.1, max=3600,
                                     help="Seconds for the search; past it, the best relaxation found is "
                                          "written, marked as not proven minimal"),
    as_json: bool = json_option("Machine-readable output: {\"plan\", \"dropped\", \"weight\", \"minimal\"} on "
                                "standard output"),
):
    """Drop the cheapest set of constraints (by weight) that makes an over-constrained plan admissible.

    Reads a plan whose strategies have cycles (YAML or JSON), or that contradicts --installed; writes
    the relaxed plan as YAML and lists the constraints dropped on standard error.
    """
    from opportune.derive.relax import RelaxRefused, constraint_lines
    from opportune.derive.relax import relax as relax_plan
    from opportune.formats.loader import CheckResult, read_plan

    result = read_plan(plan_file, allow_cycles=True)
    if not result.ok:
        if not json_invalid_plan(plan_file, result, as_json):
            print_problems(CheckResult(None, result.errors), err())
            if all(p.code == "cycle" for p in result.errors):  # cycles in a format read only when acyclic
                err().print(f"{escape(str(plan_file))}: `opportune relax` reads plans with cycles from YAML and "
                            "JSON files only: write this one as a YAML plan (parts, requires), then relax it")
            else:
                err().print(f"{escape(str(plan_file))}: {len(result.errors)} error(s); `opportune relax` drops "
                            "constraints that form cycles but cannot mend these")
        raise typer.Exit(1)
    plan = result.plan
    prefix = [p for p in (installed or "").replace(",", " ").split() if p]
    try:
        relaxation = relax_plan(plan, prefix, time_limit=time_limit, lines=constraint_lines(plan_file))
    except RelaxRefused as exc:
        fail(f"{plan_file}: {exc}; split the plan, or break the largest knot of constraints by hand")
    except ValueError as exc:
        fail(str(exc))
    text = _plan_yaml(relaxation.plan.to_dict())
    if output is not None:
        write_text(output, text)
    if as_json:
        print(json.dumps(relaxation.to_dict(), indent=2))
    elif output is None:
        sys.stdout.write(text)
    say = err()
    if not relaxation.changed:
        state = f" after {' '.join(prefix)}" if prefix else ""
        if not as_json:
            say.print(f"{escape(plan.name)}: the plan is already admissible{escape(state)}: nothing to drop; "
                      "the plan is written unchanged")
        return
    if as_json:
        return
    n = len(relaxation.dropped)
    proof = "minimal" if relaxation.minimal else "NOT PROVEN MINIMAL: the search ran out of --time-limit"
    say.print(f"{escape(plan.name)}: dropped {n} constraint{'s' if n != 1 else ''} of total weight "
              f"{relaxation.weight:g} ({proof}):")
    for d in relaxation.dropped:
        where = f", {plan_file}:{d.line}" if d.line else ""
        why = ", violated by --installed" if d.forced else ""
        say.print(f"  {escape(d.before)} -> {escape(d.after)}  (strategy '{escape(d.strategy)}', weight "
                  f"{d.weight:g}{escape(where)}{why})")
    if relaxation.repaired is not None and len(plan.strategies) > 1:
        say.print(f"strategy '{escape(relaxation.repaired)}' was relaxed to admit the installed parts (the cheapest "
                  "to repair); the other strategies are as written")
    for name, same in relaxation.removed:
        say.print(f"strategy '{escape(name)}' removed: relaxed, it admits exactly the sequences of '{escape(same)}'")
    if output is not None:
        say.print(f"wrote {escape(str(output))}")


def _plan_yaml(doc: dict) -> str:
    """A plan document as YAML that reads like a hand-written plan: short lists (parts, requirements)
    and weighted entries on one line each, ``co: [rl, dr, {part: ml, weight: 5}]``."""
    import yaml

    class Dumper(yaml.SafeDumper):
        pass

    def flat(value) -> bool:
        return not isinstance(value, (list, dict)) or (isinstance(value, dict) and
                                                       all(not isinstance(v, (list, dict)) for v in value.values()))

    def represent_list(dumper, data):
        return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=all(flat(v) for v in data))

    Dumper.add_representer(list, represent_list)
    return yaml.dump(doc, Dumper=Dumper, sort_keys=False, allow_unicode=True, width=100)
