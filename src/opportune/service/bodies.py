"""The bodies the HTTP service reads (``POST /runs``, looks, outcomes, cancels), as Pydantic models.

The models check and document a request: printable text (:data:`Text`), valid Unicode, JSON integers,
and every bound of :mod:`opportune.limits`.  The OpenAPI document names them (``RunIn``, ``LookIn``,
``OutcomeIn``, ``CancelIn``), so their names are part of the service's published interface.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal, Optional

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field
from pydantic_core import PydanticCustomError

from opportune.formats.problems import PRINTABLE
from opportune.limits import MAX_BUFFER, MAX_ID, MAX_LABEL, MAX_LOOK, MAX_NAME, MAX_PRODUCTS
from opportune.policies.named import DEFAULT_POLICY, FORMER_NAMES, POLICIES
from opportune.service.schemas import GEARBOX_PLAN_ID

__all__ = ["CancelIn", "LookIn", "OutcomeIn", "RunIn", "Text"]

_SURROGATE = re.compile("[\ud800-\udfff]")


def _unicode(text: str) -> str:
    """Refuse text with half of a UTF-16 surrogate pair (JSON's "\\ud800"): it cannot be stored or sent back."""
    if _SURROGATE.search(text):
        raise ValueError("not valid Unicode text: it contains half of a UTF-16 surrogate pair (\\ud800-\\udfff); "
                         "send the character itself or both halves of the pair")
    return text


#: Text of a request: printable (the schema states it; :class:`~opportune.service.middleware.BodyLimit` refuses a control character anywhere
#: in a request before it is read) and valid Unicode.
#: (The pattern is the schema's statement only: the middleware refuses first, and Pydantic's own check of a
#: pattern would read half of a surrogate pair as undecodable bytes rather than say what it is.)
Text = Annotated[str, AfterValidator(_unicode), Field(json_schema_extra={"pattern": PRINTABLE})]


def _json_integer(value):
    """An integer as JSON Schema has it (``4``, ``4.0``): Pydantic alone would also read ``false`` as 0 and ``"4"``
    as 4 (schemathesis found a run started with ``"buffer_capacity": false``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PydanticCustomError("int_type", "Input should be a valid integer")
    return value


class RunIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"plan": GEARBOX_PLAN_ID, "label": "SN 1042", "buffer_capacity": 4, "policy": "paper"},
        {"plan": GEARBOX_PLAN_ID}]})
    plan: Text = Field(..., min_length=1, max_length=64,
                       description="A plan id returned by POST /plans, or a plan shipped with the package by name "
                                   "(`salbp:ARC111`, `example:gearbox`, as `opportune examples` lists them), "
                                   "stored for the token's cell as it starts")
    cell: Optional[Text] = Field(None, max_length=MAX_NAME,
                                 description="The cell; defaults to (and must be) the token's cell")
    buffer_capacity: Optional[Annotated[int, Field(ge=0, le=MAX_BUFFER), BeforeValidator(_json_integer)]] = Field(
        None, description="Buffer locations; null: unlimited")
    label: Text = Field("", max_length=MAX_LABEL, description="Free text shown on the dashboard (e.g. a serial number)")
    policy: Optional[Literal[POLICIES + tuple(FORMER_NAMES)]] = Field(
        None, description=f"The decision policy (default: {DEFAULT_POLICY}, the exact look-ahead; 'paper': the "
                          "paper's rule; 'opportunistic', its former name, runs it with a `note` in the answer)")
    products: Optional[Annotated[int, Field(ge=1, le=MAX_PRODUCTS), BeforeValidator(_json_integer)]] = Field(
        None, description="Build this many copies of the plan at once on as many fixtures fed from one bin (1–16; "
                          "default 1): looks then name part kinds, and each install says its fixture")


class LookIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"visible": ["rl", "ra"]}, {"visible": []}]})
    visible: list[Annotated[Text, Field(min_length=1, max_length=MAX_ID)]] = Field(
        ..., max_length=MAX_LOOK, description="Part ids seen in the bin now, repeated for several units; [] for nothing")


class OutcomeIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [
        {"outcome": "success"}, {"outcome": "failed", "keep": "buffer"}, {"outcome": "defective"}]})
    outcome: Literal["success", "failed", "defective"] = Field(..., description="What happened to the pending action")
    keep: Literal["bin", "buffer"] = Field("bin", description="After a failed install: part back in the bin, or kept in a buffer location")


class CancelIn(BaseModel):
    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{}]})
