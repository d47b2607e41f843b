"""What every study shares: its ``--out DIR`` and the table it writes there, progress lines, comma-separated
lists and a pool that flies single flights a few at a time."""
from __future__ import annotations

import argparse
import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Callable

from quad_msgs_bridge.output_path import output_path


def study_name(module: str) -> str:
    """The command name of a study module (``flight_stack.studies.paper_tables`` -> ``paper-tables``)."""
    return module.rpartition('.')[2].replace('_', '-')


def progress(study: str, message: str) -> None:
    """One progress line of ``study`` on stderr (stdout keeps the table)."""
    print(f'study {study}: {message}', file=sys.stderr, flush=True)


def add_out(parser: argparse.ArgumentParser) -> None:
    """The folder every study writes its table into (``--out DIR``, required)."""
    parser.add_argument('--out', type=output_path, required=True, metavar='DIR',
                        help='folder for the markdown table (DIR/NAME.md; made if missing)')


def write_table(study: str, out: Path, text: str) -> Path:
    """Print the markdown ``text`` and write it to ``out/<study>.md``; the final progress line names the file."""
    print(text)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f'{study}.md'
    path.write_text(text + '\n')
    progress(study, f'wrote the markdown table {path}')
    return path


def names(text: str) -> list[str]:
    """The names of a comma-separated option (blanks dropped)."""
    return [name.strip() for name in text.split(',') if name.strip()]


def run_all(function: Callable, tasks: list, jobs: int, study: str | None = None,
            label: Callable[[object], str] = str) -> list:
    """``[function(t) for t in tasks]``, ``jobs`` at a time in worker processes when jobs > 1; with ``study``, a
    progress line as each task ends (``label(task)`` names it)."""
    def told(results):
        for done, (task, result) in enumerate(zip(tasks, results), 1):
            if study is not None:
                progress(study, f'{done}/{len(tasks)} flown: {label(task)}')
            yield result
    if jobs <= 1 or len(tasks) <= 1:
        return list(told(function(task) for task in tasks))
    method = 'fork' if 'fork' in multiprocessing.get_all_start_methods() else None
    with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context(method)) as pool:
        return list(told(pool.map(function, tasks)))
