"""Benchmarks of openel-async: ``uv run python -m benchmarks [NAME...] [--quick] [--check] [--write-docs]``.

Each benchmark is a module ``bench_<name>.py`` in this package exposing
``run(quick: bool) -> BenchResult`` (see :mod:`benchmarks.harness`); it is found by its
file name, so adding a benchmark means adding a module, nothing else. Modules are
imported only when run, so a benchmark whose dependencies are missing does not break
the others.
"""

from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path
from typing import Protocol, cast

from .harness import BenchResult

PREFIX = "bench_"


class BenchModule(Protocol):
    def run(self, quick: bool) -> BenchResult: ...


def available() -> list[str]:
    """Names of the benchmarks, in file-name order."""
    names = [
        info.name.removeprefix(PREFIX)
        for info in pkgutil.iter_modules([str(Path(__file__).parent)])
        if info.name.startswith(PREFIX)
    ]
    return sorted(names)


def load(name: str) -> BenchModule:
    module = importlib.import_module(f"{__name__}.{PREFIX}{name}")
    if not callable(getattr(module, "run", None)):
        raise TypeError(f"{module.__name__} has no run(quick: bool) -> BenchResult")
    return cast(BenchModule, module)
