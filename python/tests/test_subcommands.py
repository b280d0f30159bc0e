"""One subcommand convention for so101-learn, so101-sysid and so101-bench (so101.subcommands): each
tool's --help lists its subcommands with their summary, `TOOL NAME --help` gives that one's
options, and an unknown name is refused with the names (exit status 2)."""

from __future__ import annotations

import pytest

from so101 import subcommands
from so101.bench.__main__ import BENCHMARKS
from so101.bench.__main__ import main as bench_main
from so101.learn.cli import RECIPES
from so101.learn.cli import main as learn_main
from so101.sysid.cli import COMMANDS
from so101.sysid.cli import main as sysid_main

TOOLS = {
    "so101-learn": (learn_main, RECIPES),
    "so101-sysid": (sysid_main, COMMANDS),
    "so101-bench": (bench_main, BENCHMARKS),
}


@pytest.fixture(autouse=True)
def wide_help(monkeypatch):
    monkeypatch.setenv("COLUMNS", "400")  # each summary on its name's line


@pytest.mark.parametrize("tool", TOOLS)
def test_help_lists_every_subcommand_with_its_summary(tool, capsys):
    main, table = TOOLS[tool]
    with pytest.raises(SystemExit) as exit:
        main(["--help"])
    assert exit.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"usage: {tool} ")
    for name, subcommand in table.items():
        assert any(line.split() and line.split()[0] == name and subcommand.summary in line for line in lines), name


@pytest.mark.parametrize("tool", TOOLS)
def test_each_subcommand_answers_help_with_its_options(tool, capsys):
    main, table = TOOLS[tool]
    for name in table:
        with pytest.raises(SystemExit) as exit:
            main([name, "--help"])
        assert exit.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: {tool} {name} ") and "--help" in out, out[:300]


@pytest.mark.parametrize("tool", TOOLS)
def test_an_unknown_subcommand_is_refused_with_the_names(tool, capsys):
    main, table = TOOLS[tool]
    with pytest.raises(SystemExit) as exit:
        main(["no-such-thing"])
    assert exit.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'no-such-thing'" in err and all(name in err for name in table)


def test_a_subcommand_runs_alone_with_the_same_options(capsys):
    seen = []
    command = subcommands.Subcommand(
        "say", lambda p: p.add_argument("--times", type=int, default=1), lambda args: seen.append(args.times) or 3
    )
    assert subcommands.run_alone("tool say", command, ["--times", "4"]) == 3
    assert subcommands.main("tool", None, {"say": command}, ["say", "--times", "5"]) == 3
    assert seen == [4, 5]
