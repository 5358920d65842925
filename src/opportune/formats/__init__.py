"""Plan files: YAML and JSON (one schema), SALBP ``.IN2`` graphs, checking and drawing."""

from opportune.formats.loader import CheckResult, check_text, load_plan, plan_from_dict, read_plan
from opportune.formats.problems import Problem

__all__ = ["CheckResult", "Problem", "check_text", "load_plan", "plan_from_dict", "read_plan"]
