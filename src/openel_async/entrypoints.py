"""The entry points of the installed distributions, read without importing
``importlib.metadata``.

The command line reads entry-point groups at every start: its drivers' commands
(``openel-async --help``), the apps (``run NAME``), the drivers (``devices``). Importing
``importlib.metadata`` alone takes 40-60 ms (it loads email, zipfile, csv and more), a
fifth of ``openel-async --help``. :func:`entry_points` reads the ``entry_points.txt`` of
each ``*.dist-info`` and ``*.egg-info`` folder in the folders of ``sys.path``, as
importlib.metadata's path finder does: in ``sys.path`` order, the first distribution of a
(normalized) name wins. Where that is not the whole picture (a zip file or an ``.egg`` on
the path, a finder on ``sys.meta_path`` with distributions of its own) it asks
importlib.metadata instead.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import os
import re
import sys
from dataclasses import dataclass
from typing import Any

__all__ = ["EntryPoint", "entry_points"]

_SUFFIXES = (".dist-info", ".egg-info")


@dataclass(frozen=True, slots=True)
class EntryPoint:
    """One entry point: ``name = value`` in ``[group]`` (``value``: ``module:attr``)."""

    name: str
    value: str
    group: str

    def load(self) -> Any:
        """Import the module and return the object ``value`` names."""
        target = self.value.split("[", 1)[0]  # no extras
        module, _, attrs = target.partition(":")
        found: Any = importlib.import_module(module.strip())
        for attr in filter(None, attrs.strip().split(".")):
            found = getattr(found, attr)
        return found


def entry_points(group: str) -> list[EntryPoint]:
    """The entry points of ``group`` of every installed distribution, in ``sys.path`` order
    (what ``importlib.metadata.entry_points(group=group)`` gives)."""
    texts = _entry_point_texts()
    if texts is None:
        from importlib import metadata

        return [EntryPoint(ep.name, ep.value, group) for ep in metadata.entry_points(group=group)]
    return [ep for text in texts for ep in _parse(text) if ep.group == group]


def _entry_point_texts() -> list[str] | None:
    """The ``entry_points.txt`` of each distribution on ``sys.path`` (None: a path this does
    not read; importlib.metadata must)."""
    if any(
        hasattr(finder, "find_distributions") and finder is not importlib.machinery.PathFinder
        for finder in sys.meta_path
    ):
        return None
    seen: set[str] = set()
    texts: list[str] = []
    for root in sys.path:
        folder = root or "."
        try:
            children = os.listdir(folder)
        except (FileNotFoundError, NotADirectoryError):
            if os.path.isfile(folder):  # a zip file: importlib.metadata reads it
                return None
            continue
        except OSError:  # unreadable: importlib.metadata skips it too
            continue
        for child in children:
            low = child.lower()
            if low.endswith(".egg"):
                return None
            if not low.endswith(_SUFFIXES):
                continue
            name = _normalize(os.path.splitext(child)[0].partition("-")[0])
            if name in seen:  # an earlier folder of sys.path has this distribution
                continue
            seen.add(name)
            try:
                with open(os.path.join(folder, child, "entry_points.txt"), encoding="utf-8") as f:
                    texts.append(f.read())
            except OSError:  # none (or an egg-info file): no entry points
                continue
    return texts


def _normalize(name: str) -> str:
    """A distribution's name as importlib.metadata compares them (PEP 503, ``_`` for ``-``)."""
    return re.sub(r"[-_.]+", "-", name).lower().replace("-", "_")


def _parse(text: str) -> list[EntryPoint]:
    """The entries of an ``entry_points.txt`` (an INI file: ``[group]``, ``name = value``)."""
    found: list[EntryPoint] = []
    group: str | None = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.startswith("[") and line.endswith("]"):
            group = line.strip("[]")
            continue
        name, equals, value = line.partition("=")
        if group is not None and equals:
            found.append(EntryPoint(name.strip(), value.strip(), group))
    return found
