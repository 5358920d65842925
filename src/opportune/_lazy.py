"""Names of a package loaded on first use (PEP 562), so that importing the package is cheap.

>>> import types
>>> m = types.ModuleType("demo")
>>> m.__getattr__, m.__dir__ = attach(vars(m), {"sqrt": "math"}, ["sqrt"])
>>> m.sqrt(9.0)
3.0
"""

from __future__ import annotations


def attach(namespace: dict, lazy: dict[str, str], public: list[str]):
    """``(__getattr__, __dir__)`` for a package whose names ``lazy`` maps to the modules that define
    them: each is imported on first use and then kept in ``namespace`` (the package's globals)."""

    def __getattr__(name: str):
        if name in lazy:
            # __import__ rather than importlib.import_module: `python -X importtime` then shows what loaded
            value = getattr(__import__(lazy[name], fromlist=(name,)), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {namespace.get('__name__')!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(public))

    return __getattr__, __dir__
