"""The sequencer as an HTTP service for robot cells, with a live dashboard (issue 6).

A cell controller (a robot program, a PLC gateway, a ROS node) drives a *run* —
one plan being assembled in one cell — by posting looks and outcome reports;
the service answers with the action the library's :class:`~opportune.sequencer.Sequencer`
decides, after committing the look, the decision and the outcome to the
database.  People watch runs live in a browser at ``/``.

Modules, one job each:

* :mod:`~opportune.service.config` — settings (database URL, limits);
* :mod:`~opportune.service.storage` — the tables and transactions (SQLAlchemy Core);
* :mod:`~opportune.service.auth` — bearer tokens, principals, short-lived SSE tickets;
* :mod:`~opportune.service.idempotency` — request hashing and stored answers;
* :mod:`~opportune.service.plans` — plan upload (validated as ``opportune check``) and the plan cache;
* :mod:`~opportune.service.runs` — live sequencers rebuilt from the event log, commands on runs;
* :mod:`~opportune.service.views` — the JSON shapes of runs, rows and decisions;
* :mod:`~opportune.service.graph` — a layered layout of the precedence graph for the dashboard;
* :mod:`~opportune.service.events` — server-sent events;
* :mod:`~opportune.service.errors` — JSON errors that say where and what to do;
* :mod:`~opportune.service.app` — the FastAPI application, put together from:
  :mod:`~opportune.service.routers` (the routes, one module a resource), :mod:`~opportune.service.bodies`
  (the request bodies), :mod:`~opportune.service.middleware` (limits, headers, timing, the last-resort
  500) and :mod:`~opportune.service.handlers` (refusals as JSON errors);
* :mod:`~opportune.service.server` — uvicorn with logs that never show a credential;
* :mod:`~opportune.service.testing` — a real server on a loopback port, for integration tests.

Its commands (``opportune serve``, ``opportune token ...``, ``opportune opcua cert``) are the command
line's, in :mod:`opportune.cli.service`.  Nothing here is imported by the library: FastAPI, uvicorn and
SQLAlchemy are the ``service`` extra.
"""
