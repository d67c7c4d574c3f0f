"""Progress of long jobs: one protocol, silent by default, drawn with rich on the command line.

A job takes a ``progress`` argument and reports each of its stages as a task::

    def run(plan, progress: Progress = SILENT):
        with progress.task("trials", total=len(plan)) as task:
            for trial in plan:
                ...
                task.advance(note=f"last: {trial}")

A task of unknown length (``total=None``) is a stage with a spinner. Library code never prints:
the command line passes a :class:`RichProgress`, tests a recorder of their own.
"""

from __future__ import annotations

import threading
from typing import Any


class Task:
    """One stage of a job. This base is silent; reporters override it."""

    def advance(self, steps: float = 1, note: str | None = None) -> None:
        """``steps`` more units of the stage are done; ``note``: a short word on the latest one."""

    def done(self) -> None:
        """The stage is over (called when a ``with`` block of the task ends)."""

    def __enter__(self) -> Task:
        return self

    def __exit__(self, *exception: Any) -> None:
        self.done()


class Progress:
    """Where a job reports its stages. This base reports nowhere: it is the default, :data:`SILENT`."""

    def task(self, description: str, total: float | None = None) -> Task:
        """A new stage: ``total`` units (None: unknown)."""
        return Task()


SILENT = Progress()


class RichProgress(Progress):
    """Bars on a rich console while tasks run; every finished task leaves one line with its duration.

    The live display runs only while a task is open, so a job may give the terminal to a live view of
    its own (the dashboard) between its stages. With ``lines`` there are no bars: a line when a task starts
    (what the user waits for), one at every tenth of a task of known length, and the finished line - what
    a log or a terminal showing ``--json`` output keeps readable.
    """

    def __init__(self, console: Any, lines: bool = False):
        from rich.progress import BarColumn, MofNCompleteColumn, SpinnerColumn, TextColumn, TimeElapsedColumn
        from rich.progress import Progress as Bars

        self._bars = Bars(SpinnerColumn(), TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                          TimeElapsedColumn(), TextColumn("{task.fields[note]}"), console=console, transient=True)
        self._lock = threading.Lock()
        self._open = 0
        self._lines = lines
        self._tenths: dict[int, int] = {}  # with lines: the tenths of each task already reported

    def task(self, description: str, total: float | None = None) -> Task:
        with self._lock:
            if not self._open and not self._lines:
                self._bars.start()
            self._open += 1
            if self._lines:
                self._bars.console.print(f"… {description}", highlight=False, markup=False, soft_wrap=True)
            task_id = self._bars.add_task(description, total=total, note="")
            self._tenths[task_id] = 0
            return _RichTask(self, task_id)

    def _advance(self, task_id: int, steps: float, note: str | None) -> None:
        self._bars.update(task_id, advance=steps, **({} if note is None else {"note": note}))
        if self._lines:
            task = next(t for t in self._bars.tasks if t.id == task_id)
            tenths = int(10 * task.completed / task.total) if task.total else 0
            if 0 < tenths < 10 and tenths > self._tenths[task_id]:
                self._tenths[task_id] = tenths
                self._bars.console.print(f"… {task.description}: {task.completed:g}/{task.total:g} "
                                         f"({task.elapsed or 0.0:.1f} s)", highlight=False, markup=False,
                                         soft_wrap=True)

    def _finish(self, task_id: int) -> None:
        with self._lock:
            task = next(t for t in self._bars.tasks if t.id == task_id)
            count = f"{task.completed:g}/{task.total:g}, " if task.total else ""
            self._bars.console.print(f"[green]✓[/] {task.description} ({count}{task.elapsed or 0.0:.1f} s)",
                                     highlight=False, soft_wrap=True)
            self._bars.remove_task(task_id)
            del self._tenths[task_id]
            self._open -= 1
            if not self._open and not self._lines:
                self._bars.stop()


class _RichTask(Task):
    def __init__(self, owner: RichProgress, task_id: int):
        self._owner, self._id, self._finished = owner, task_id, False

    def advance(self, steps: float = 1, note: str | None = None) -> None:
        self._owner._advance(self._id, steps, note)

    def done(self) -> None:
        if not self._finished:
            self._finished = True
            self._owner._finish(self._id)
