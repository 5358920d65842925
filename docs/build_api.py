"""Write docs/api.md, the API reference, from the package's own docstrings.

    python docs/build_api.py            # rewrite docs/api.md
    python docs/build_api.py --check    # exit 1 if docs/api.md is out of date (a test runs this)

The reference follows the decision path of the package: plans, the order engine, the sequencer,
policies, worlds, the simulation study.  Each entry gives the signature and the docstring as written.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

# (module, names, what the section is for) in the order a user meets them
SECTIONS = [
    ("opportune.plan", ["Part", "Strategy", "Plan", "PlanError", "make_plan"], "Plans: parts and strategies"),
    ("opportune.formats.loader", ["load_plan", "read_plan", "check_text", "plan_from_dict", "CheckResult"],
     "Reading and checking plan files"),
    ("opportune.formats.graphfiles", ["check_graphml_bytes", "check_dot_bytes", "to_graphml", "to_dot_precedence",
                                      "plan_to_networkx", "plan_from_networkx"], "Precedence graphs as files"),
    ("opportune.datasets", ["salbp", "salbp_path", "salbp_names", "examples", "example_path", "resolve"],
     "Data shipped with the package"),
    ("opportune.engine.poset", ["Poset"], "Partial orders"),
    ("opportune.engine.count", ["Counter", "BudgetExceeded", "count_linear_extensions"],
     "Counting linear extensions"),
    ("opportune.engine.native", ["available", "native_counter", "NativeCounter"], "The compiled core"),
    ("opportune.engine.schedule", ["OrderEngine", "Schedule", "CountResult", "NotAdmissible"],
     "The schedule: what is done and every admissible way to finish"),
    ("opportune.engine.estimate", ["estimate_count"], "Estimates with a stated error"),
    ("opportune.engine.sampling", ["CompletionChains"], "Random completions"),
    ("opportune.sequencer", ["Sequencer"], "The sequencer"),
    ("opportune.policies.base", ["Action", "Decision", "Candidate", "Estimate", "Policy"], "Actions and decisions"),
    ("opportune.policies.opportunistic", ["Opportunistic"], "The paper's rule"),
    ("opportune.policies.variants", ["BinFirst", "Slack", "Lookahead"], "Policies beyond the paper's rule"),
    ("opportune.policies.optimal", ["OptimalSolver", "Optimal"], "The optimum"),
    ("opportune.policies.evaluate", ["PolicyEvaluator"], "Exact policy evaluation"),
    ("opportune.policies.pile", ["PileSolver"], "The pile bin"),
    ("opportune.simulate", ["StudyConfig", "run_study", "prepare", "StudyResult", "TrialResult"],
     "The simulation study"),
    ("opportune.report", ["summary", "write_outputs", "describe"], "Tables, files and plots"),
]


def signature(obj) -> str:
    try:
        return str(inspect.signature(obj))
    except (TypeError, ValueError):
        return ""


def entry(name: str, obj) -> list[str]:
    kind = "class" if inspect.isclass(obj) else "function" if callable(obj) else "value"
    out = [f"### `{name}{signature(obj) if kind != 'value' else ''}`", ""]
    doc = inspect.getdoc(obj) or "(no docstring)"
    out += [doc, ""]
    if kind == "class":
        for attr, member in sorted(vars(obj).items()):
            if attr.startswith("_") or not (inspect.isfunction(member) or isinstance(member, (property, staticmethod,
                                                                                             classmethod))):
                continue
            func = member.fget if isinstance(member, property) else getattr(member, "__func__", member)
            first = (inspect.getdoc(func) or "").split("\n\n")[0].replace("\n", " ")
            sig = "" if isinstance(member, property) else signature(func)
            out.append(f"- `{attr}{sig}`" + (f": {first}" if first else ""))
        out.append("")
    return out


def build() -> str:
    lines = ["# API reference", "",
             "Generated from the docstrings by `docs/build_api.py` (a test checks it is up to date). The",
             "command line is described in the README; `opportune COMMAND --help` gives every option.", ""]
    for module_name, names, title in SECTIONS:
        module = importlib.import_module(module_name)
        lines += [f"## {title} (`{module_name}`)", ""]
        summary = (inspect.getdoc(module) or "").split("\n\n")[0]
        if summary:
            lines += [summary, ""]
        for name in names:
            lines += entry(name, getattr(module, name))
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/api.md differs from what would be written")
    args = ap.parse_args(argv)
    text = build()
    path = HERE / "api.md"
    if args.check:
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            print("docs/api.md is out of date: run `python docs/build_api.py`", file=sys.stderr)
            return 1
        return 0
    path.write_text(text, encoding="utf-8")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
