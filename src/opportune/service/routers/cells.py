"""``/cells``: the cells with their numbers of runs."""

from __future__ import annotations

from typing import Callable

from fastapi import APIRouter, Depends

from opportune.service.auth import Principal
from opportune.service.runs import RunManager
from opportune.service.schemas import CellList, errors

__all__ = ["router"]


def router(manager: RunManager, principal: Callable[..., Principal]) -> APIRouter:
    """The cells' route over ``manager``; ``principal``: the dependency that says who is asking."""
    api = APIRouter()

    @api.get("/cells", tags=["runs"], operation_id="listCells",
             summary="Cells with their numbers of runs (a cell token sees itself)",
             responses={200: {"model": CellList}, **errors({401: ["unauthorized"], 500: ["internal_error"]})})
    def list_cells(p: Principal = Depends(principal)):
        return {"cells": manager.cells(p)}

    return api
