"""Lazy package exports (PEP 562): a package lists its public names and the module each
comes from; a name's module is imported on first use, so importing the package (or one of
its light modules, e.g. a command line's parser) does not load every dependency.

A package's ``__init__``::

    if TYPE_CHECKING:
        from .client import RemoteSurface  # for type checkers and IDEs

    __getattr__, __dir__ = lazy_exports(__name__, {"RemoteSurface": "client"})

And a module global bound to another module's function at its first call
(:func:`first_use`), for a module that must not import that one when it is loaded (the
clocks and asyncio: an app printing its ``--help`` never waits).
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["first_use", "lazy_exports"]


def lazy_exports(
    package: str,
    names: Mapping[str, str],
    factories: Mapping[str, Callable[[], Any]] | None = None,
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` of ``package``.

    ``names`` maps a public name to the submodule (relative to ``package``) that defines it;
    ``factories`` maps a name to a function that builds its value (a driver's ``DRIVER``).
    A value is cached in the package's namespace on first use."""
    builders = dict(factories or {})

    def __getattr__(name: str) -> Any:
        builder = builders.get(name)
        if builder is not None:
            value = builder()
        else:
            module = names.get(name)
            if module is None:
                raise AttributeError(f"module {package!r} has no attribute {name!r}")
            value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *names, *builders})

    return __getattr__, __dir__


def first_use(namespace: dict[str, Any], name: str, module: str, attr: str) -> Any:
    """A stand-in for ``module.attr``, to be stored as the global ``name`` of ``namespace``
    (the calling module's ``globals()``): its first call imports ``module``, rebinds the
    global to ``module.attr`` itself and returns that call's result, so every later call is
    the function's own (no stand-in frame, no import per call)."""

    def stand_in(*args: Any, **kwargs: Any) -> Any:
        target = getattr(importlib.import_module(module), attr)
        namespace[name] = target
        return target(*args, **kwargs)

    return stand_in
