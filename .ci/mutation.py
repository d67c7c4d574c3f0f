"""Mutation testing (mutmut) of the modules [tool.softtip.mutation.tests] in pyproject.toml names,
each against its own fast test files; run by .ci/mutation, which says how.

    python .ci/mutation.py run [SOURCE ...]     mutmut run, its output to mutation.log
    python .ci/mutation.py rerun [SOURCE ...]   the survivors of the last run again, against the tests as
                                                they now are (new tests included)
    python .ci/mutation.py report [SOURCE ...]  the figures, per module and in all

SOURCE: modules as the table names them (src/softtip/...py); none: all of them. Only the given
modules are mutated and only their test files are run (a module alone takes minutes, all of them an
hour or more on 2 cores). The report writes every surviving mutant's diff to mutation-survivors.txt
and counts a survivor that .ci/mutation-equivalent.toml lists, with the line the mutant writes and
why that changes nothing, as an equivalent mutant: out of the figure. A listed mutant whose line is
no longer the one it writes (the source changed) counts as a survivor again, and is said to be stale.
"""

from __future__ import annotations

import collections
import shutil
import sys
import tomllib
from pathlib import Path

from mutmut.__main__ import cli
from mutmut.configuration import config
from mutmut.mutation.data import SourceFileMutationData
from mutmut.mutation.diff_apply import get_diff_for_mutant
from mutmut.stats import status_by_exit_code

MIN_CAUGHT_PERCENT = 90  # on each module and in all
CAUGHT = ("killed", "timeout")  # a mutant that makes the tests hang is caught too
EQUIVALENT_FILE = Path(".ci/mutation-equivalent.toml")


def tests_by_module() -> dict[str, list[str]]:
    return tomllib.loads(Path("pyproject.toml").read_text())["tool"]["softtip"]["mutation"]["tests"]


def select(modules: list[str]) -> list[str]:
    """Points mutmut at ``modules`` (all of the table's when empty) and their test files only."""
    table = tests_by_module()
    unknown = [module for module in modules if module not in table]
    if unknown:
        sys.exit(f"error: {', '.join(unknown)}: not under [tool.softtip.mutation.tests] in pyproject.toml "
                 f"(expected one of {', '.join(table)})")
    modules = modules or list(table)
    settings = config()
    settings.only_mutate = modules
    settings.pytest_add_cli_args_test_selection = sorted({test for module in modules for test in table[module]})
    return modules


def outcomes(module: str) -> dict[str, str]:
    """Each mutant of ``module`` and what became of it in the last run."""
    data = SourceFileMutationData(path=Path(module))
    data.load()
    return {name: status_by_exit_code[code] for name, code in data.exit_code_by_key.items()}


def changed_lines(mutant: str) -> list[str]:
    """The lines the mutant writes (the diff's + lines), stripped."""
    diff = get_diff_for_mutant(mutant)
    return [line[1:].strip() for line in diff.splitlines() if line.startswith("+") and not line.startswith("+++")]


def report(modules: list[str], minimum_percent: float) -> bool:
    equivalent = {entry["mutant"]: entry for entry in tomllib.loads(EQUIVALENT_FILE.read_text())["equivalent"]}
    figures_met = True
    totals = collections.Counter()
    with open("mutation-survivors.txt", "w") as log:
        for module in modules:
            counts = collections.Counter()
            for name, status in sorted(outcomes(module).items()):
                if status in CAUGHT:
                    counts["caught"] += 1
                    if name in equivalent:
                        print(f"stale: {name} is listed as equivalent but was {status}")
                    continue
                entry = equivalent.get(name)
                if entry is not None and entry["line"].strip() in changed_lines(name):
                    counts["equivalent"] += 1
                    continue
                if entry is not None:
                    print(f"stale: {name} no longer writes {entry['line'].strip()!r}: counted as {status}")
                counts["survived"] += 1
                print(f"{status}: {name}")
                log.write(f"# {name}: {status}\n{get_diff_for_mutant(name)}\n")
            totals += counts
            figures_met &= print_figure(module, counts, minimum_percent)
    if len(modules) > 1:
        figures_met &= print_figure("all", totals, minimum_percent)
    return figures_met


def print_figure(what: str, counts: collections.Counter, minimum_percent: float) -> bool:
    judged = counts["caught"] + counts["survived"]
    percent = 100 * counts["caught"] / judged if judged else 100.0
    print(f"{what}: {counts['caught']} caught (killed or timed out) of {judged} mutants, {percent:.1f} % "
          f"({counts['equivalent']} equivalent left out)")
    return percent >= minimum_percent


def main() -> None:
    action, *modules = sys.argv[1:]
    modules = select(modules)
    if action == "run":
        cli.main(["run", "--max-children", "1"], standalone_mode=False)
    elif action == "rerun":
        # mutmut copies the tests once: bring over the ones written or changed since, and forget which
        # test reaches which function (a changed test may reach more), so that it is collected again
        shutil.copytree("tests", "mutants/tests", dirs_exist_ok=True)
        Path("mutants/mutmut-stats.json").unlink(missing_ok=True)
        equivalent = {entry["mutant"] for entry in tomllib.loads(EQUIVALENT_FILE.read_text())["equivalent"]}
        survivors = [name for module in modules for name, status in outcomes(module).items()
                     if status not in CAUGHT and name not in equivalent]  # the report checks those
        if survivors:
            cli.main(["run", "--max-children", "1", *survivors], standalone_mode=False)
    elif action == "report":
        sys.exit(0 if report(modules, MIN_CAUGHT_PERCENT) else 1)
    else:
        sys.exit(f"error: {action}: expected run or report")


if __name__ == "__main__":
    main()
