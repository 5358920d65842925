"""Policies: what to do at each look.  All share the :class:`~opportune.policies.base.Policy` interface."""

from opportune.policies.base import Action, Candidate, Decision, Policy
from opportune.policies.opportunistic import Opportunistic

__all__ = ["Action", "Candidate", "Decision", "Opportunistic", "Policy"]
