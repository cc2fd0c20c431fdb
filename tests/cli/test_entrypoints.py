"""openel_async.entrypoints reads the entry points importlib.metadata would give, without
importing it (issue 27: start-up of the command line)."""

from __future__ import annotations

import sys
import zipfile
from importlib import metadata
from pathlib import Path

import pytest

from openel_async.entrypoints import EntryPoint, entry_points


def entry_points_of_importlib(group: str) -> list[EntryPoint]:
    return [EntryPoint(ep.name, ep.value, group) for ep in metadata.entry_points(group=group)]


def _groups() -> set[str]:
    return {ep.group for dist in metadata.distributions() for ep in dist.entry_points}


def test_every_group_reads_as_importlib_metadata_reads_it() -> None:
    groups = _groups() | {"openel_async.commands", "openel_async.apps", "openel_async.drivers"}
    for group in sorted(groups):
        ours = [(ep.name, ep.value, ep.group) for ep in entry_points(group)]
        assert ours == [(ep.name, ep.value, ep.group) for ep in entry_points_of_importlib(group)]
    assert {ep.name for ep in entry_points("openel_async.apps")} >= {"arm2", "twoaxis"}


def test_an_entry_point_loads_the_object_it_names() -> None:
    assert EntryPoint("x", "os.path:join", "g").load() is __import__("os").path.join
    assert EntryPoint("x", "os : path.join [extra]", "g").load() is __import__("os").path.join
    assert EntryPoint("x", "os.path", "g").load() is __import__("os").path


def test_a_distribution_first_on_the_path_hides_a_later_one_of_its_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for folder, dist, value in (("a", "My_Pkg-1.0", "first:x"), ("b", "my.pkg-2.0", "second:x")):
        info = tmp_path / folder / f"{dist}.dist-info"
        info.mkdir(parents=True)
        (info / "entry_points.txt").write_text(
            f"# a comment\n[other]\nz = zz:z\n\n[test.group]\n  name =  {value}  \n"
        )
    monkeypatch.setattr(sys, "path", [str(tmp_path / "a"), str(tmp_path / "b")])
    assert entry_points("test.group") == [EntryPoint("name", "first:x", "test.group")]
    assert entry_points("test.group") == entry_points_of_importlib("test.group")


def test_a_zip_file_on_the_path_is_left_to_importlib_metadata(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    archive = tmp_path / "dists.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        zf.writestr("zipped-1.0.dist-info/entry_points.txt", "[test.group]\nz = zipped:z\n")
        zf.writestr("zipped-1.0.dist-info/METADATA", "Name: zipped\nVersion: 1.0\n")
    monkeypatch.setattr(sys, "path", [str(archive)])
    # (read by importlib.metadata: this module reads folders only)
    assert entry_points("test.group") == [EntryPoint("z", "zipped:z", "test.group")]
