"""What every front end of the service shares: the store, the plan book, the authenticator and the run manager.

The HTTP application (:func:`opportune.service.app.create_app`) and the OPC UA server
(:mod:`opportune.service.opcua`) are front ends over one :class:`Core`: served together by one
``opportune serve``, they drive the same runs through the same run manager, so a run started
over one protocol is the same run over the other.  No web framework is imported here.

>>> core = build(Settings(db_url="sqlite:///cell.db"))             # doctest: +SKIP
>>> core.manager.view(principal, run_id)                           # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from opportune.service.auth import Authenticator
from opportune.service.config import Settings
from opportune.service.plans import PlanBook
from opportune.service.runs import RunManager
from opportune.service.storage import Store


@dataclass
class Core:
    """The service's shared state: one of each per server process."""

    settings: Settings
    store: Store
    book: PlanBook
    auth: Authenticator
    manager: RunManager

    def close(self) -> None:
        self.book.close()
        self.store.dispose()


def build(settings: Settings, store: Store | None = None, *, notify: Callable[[int], None] = lambda _: None) -> Core:
    """The core over ``store`` (opened from ``settings.db_url`` if not given); ``notify(run_id)`` is called after
    every committed change of a run.  O(1): plans load on first use."""
    store = store or Store(settings.db_url)
    book = PlanBook(store, count_seconds=settings.count_seconds, memory_cap=settings.memory_cap,
                    plan_share=settings.plan_share)
    auth = Authenticator(store, cache_seconds=settings.token_cache_seconds, ticket_seconds=settings.ticket_seconds)
    manager = RunManager(store, book, size=settings.live_runs, notify=notify,
                         keep_answers=settings.idempotency_seconds, budget=settings.decision_budget,
                         warm_up=settings.warm_up_seconds, optimum=settings.optimum_seconds)
    return Core(settings, store, book, auth, manager)
