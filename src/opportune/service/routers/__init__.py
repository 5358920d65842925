"""The HTTP service's routes, one module a resource; :func:`opportune.service.app.create_app` includes them.

* :mod:`~opportune.service.routers.dashboard` — the pages (dashboard, a run's page, the API's reader) and
  ``/healthz``;
* :mod:`~opportune.service.routers.plans` — ``/plans``: upload, list, read;
* :mod:`~opportune.service.routers.cells` — ``/cells``;
* :mod:`~opportune.service.routers.runs` — ``/runs``: start, list, read, looks, outcomes, cancels;
* :mod:`~opportune.service.routers.events` — a run's live updates: tickets and the event stream;
* :mod:`~opportune.service.routers.depends` — what the routers share: who is asking, the run id, the
  ``Idempotency-Key`` header, replayable answers.

Each module's ``router(...)`` takes what its routes use (the store, the plan book, the run manager, the
dependency that says who is asking) and returns an :class:`fastapi.APIRouter`: no router reads another's
names or the application's.
"""
