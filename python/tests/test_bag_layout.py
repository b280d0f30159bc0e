"""The Python reader finds episodes and orders their files as so101_core::episode_bag does: both
run the cases of tests/fixtures/episode_bags.txt."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest

from so101.dataset.bags import BagError, episode_dirs, mcap_files
from so101.paths import repo_root


@dataclass
class Case:
    name: str
    tree: list[str] = field(default_factory=list)
    given: list[str] = field(default_factory=list)
    episodes: list[str] | None = None
    mcap: list[str] | None = None


def cases() -> list[Case]:
    found: list[Case] = []
    for line in (repo_root() / "tests" / "fixtures" / "episode_bags.txt").read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        key, _, value = line.partition(":")
        words = value.split()
        if key == "case":
            found.append(Case(value.strip()))
        elif key == "episodes":
            found[-1].episodes = None if words == ["error"] else words
        else:
            setattr(found[-1], key, words)
    return found


@pytest.mark.parametrize("case", cases(), ids=lambda case: case.name)
def test_the_shared_layout_cases_hold(case: Case, tmp_path: Path):
    for entry in case.tree:
        path = tmp_path / entry
        if entry.endswith("/"):
            path.mkdir(parents=True, exist_ok=True)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(b"")
    given = [tmp_path / g for g in case.given]
    if case.episodes is None:
        with pytest.raises(BagError):
            episode_dirs(given)
        return
    found = episode_dirs(given)
    assert [str(p.relative_to(tmp_path)) for p in found] == case.episodes
    if case.mcap is not None:
        assert [p.name for p in mcap_files(found[0])] == case.mcap


def test_there_are_cases():
    assert len(cases()) >= 5
