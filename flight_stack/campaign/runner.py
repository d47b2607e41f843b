"""Running a campaign: batches on local worker processes or on a Dask cluster, results streamed to disk.

A campaign is a list of independent :class:`~.batch.BatchJob` (one controller, up to
``batch_size`` flights). Local runs use a process pool (one process per worker, default: every
core); with a scheduler address the jobs go to an existing Dask distributed cluster (``dask
scheduler`` / ``dask worker``; a scheduler runs whatever code it is sent: use it on a trusted
network only). Every finished batch is appended to ``flights.csv`` at once, so Ctrl-C or a crash
loses no finished batch, and ``resume`` flies only the missing (flight, controller) pairs.

The batches are planned lazily (a generator), and only a few are handed to the workers ahead of
the ones flying, so the memory of a campaign does not grow with its number of flights. The
kernels are compiled (or loaded from numba's cache) in this process before the first batch, so
the workers find them in the cache. SIGINT (Ctrl-C) and SIGTERM stop a campaign at any phase
within about a second: the workers are terminated, and the finished batches stay in flights.csv.
"""
from __future__ import annotations

import ast
import contextlib
import json
import math
import multiprocessing
import os
import signal
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterator

import yaml

from nnit2fsmc_controller.factory import gains_flown_by
from nnit2fsmc_controller.registry import controller_kind
from quad_msgs_bridge.validation import ParameterError

from ..interrupts import stop_signals
from ..locking import FileLock
from .batch import COLUMNS, BatchJob, CampaignSetup, compile_kernels, fly_batch
from .results import FLIGHTS_FILE, SUMMARY_FILE, FlightsFile, read_flights, summarize
from .spec import CampaignSpec

SPEC_FILE = 'spec.yaml'
#: what a campaign flies beyond its spec (:func:`campaign_inputs`): a resume must fly the same
INPUTS_FILE = 'inputs.yaml'
LOCK_FILE = '.campaign.lock'
MAX_BATCH_SIZE = 1000           #: the default batch size's cap (flights stepped together; what an interruption may lose per worker)
#: batches handed to the workers ahead of the ones flying, per worker (a bound on what waits in memory)
QUEUED_PER_WORKER = 2


@dataclass(frozen=True)
class RunOptions:
    workers: int | None = None          #: local processes (default: every core)
    batch_size: int | None = None       #: flights per batch (default: an even share per worker, at most 1000)
    scheduler: str | None = None        #: Dask scheduler address, e.g. tcp://127.0.0.1:8786
    resume: bool = False
    progress: bool = True
    vehicle_file: str | None = None
    gains_file: str | None = None
    report: bool = True                 #: write report.html (with its plots) beside campaign.json
    progress_label: str = 'campaign'    #: what the progress bar of the flights is called

    def worker_count(self) -> int:
        """The local worker processes to use; ParameterError on an invalid --workers or --batch-size."""
        _positive_int('--workers', self.workers)
        _positive_int('--batch-size', self.batch_size)
        return self.workers or os.cpu_count() or 1


def _positive_int(name: str, value) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ParameterError(f'{name}: {value!r} is not a whole number >= 1')
    return value


def batch_size(spec: CampaignSpec, options: RunOptions, workers: int) -> int:
    """Flights per batch: ``options.batch_size``, else an even share per worker, at most MAX_BATCH_SIZE."""
    return options.batch_size or max(1, min(MAX_BATCH_SIZE, math.ceil(spec.flights / workers)))


def plan_jobs(spec: CampaignSpec, done: set, options: RunOptions, workers: int) -> Iterator[BatchJob]:
    """The batches still to fly, one at a time: for each controller, its missing flights in chunks of the
    batch size. A generator: a campaign of 10^9 flights plans its first batch without listing the rest."""
    size = batch_size(spec, options, workers)
    for controller in spec.controllers:
        flights: list[int] = []
        for k in range(spec.flights):
            if (k, controller) in done:
                continue
            flights.append(k)
            if len(flights) == size:
                yield BatchJob(spec, controller, tuple(flights), options.vehicle_file, options.gains_file)
                flights = []
        if flights:
            yield BatchJob(spec, controller, tuple(flights), options.vehicle_file, options.gains_file)


def flights_to_fly(spec: CampaignSpec, done: set) -> int:
    """How many (flight, controller) pairs of ``spec`` are not in ``done``."""
    flown = sum(1 for k, controller in done if controller in spec.controllers and 0 <= k < spec.flights)
    return spec.flights * len(spec.controllers) - flown


def holds_campaign(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a campaign (begun or finished: one only ``resume`` continues)."""
    return (out_dir / FLIGHTS_FILE).exists() or (out_dir / SPEC_FILE).exists()


def campaign_inputs(spec: CampaignSpec, setup: CampaignSetup) -> dict:
    """What a campaign flies beyond its spec, as plain data: the nominal vehicle and its section IV
    disturbances (the vehicle file's values) and, per controller, the gains it flies (the ``common`` section
    and its own: :func:`gains_flown_by`, so a gains file changed only in another kind's section still
    resumes)."""
    document = {'vehicle': asdict(setup.nominal), 'disturbances': asdict(setup.disturbances),
                'gains': {kind: gains_flown_by(kind, setup.gains) for kind in spec.controllers}}
    return json.loads(json.dumps(document, default=lambda value: value.tolist()))


def _first_difference(stored, now, path: str = '') -> str:
    """The first key (dotted) where two plain documents differ, with both values."""
    if isinstance(stored, dict) and isinstance(now, dict):
        for key in sorted(set(stored) | set(now), key=str):
            if stored.get(key) != now.get(key):
                return _first_difference(stored.get(key), now.get(key), f'{path}.{key}' if path else str(key))
    return f'{path}: {stored!r} there, {now!r} now'


def check_inputs(out_dir: Path, inputs: dict) -> None:
    """ParameterError if the campaign in ``out_dir`` flew another vehicle or, for a controller of ``inputs``,
    other gains (its INPUTS_FILE; a folder written before that file existed is not checked)."""
    path = out_dir / INPUTS_FILE
    if not path.exists():
        return
    stored = yaml.safe_load(path.read_text()) or {}
    for part in ('vehicle', 'disturbances'):
        if stored.get(part) != inputs[part]:
            raise ParameterError(f'--resume: the campaign in {out_dir} flew another vehicle file '
                                 f'({_first_difference(stored.get(part), inputs[part], part)}); resume it with '
                                 'the same --vehicle')
    for kind, gains in inputs['gains'].items():
        flown = stored.get('gains', {}).get(kind)
        if flown is not None and flown != gains:
            raise ParameterError(f'--resume: the campaign in {out_dir} flew {kind} with other gains '
                                 f'({_first_difference(flown, gains)}); resume it with the same --gains')


def check_output(spec: CampaignSpec, out_dir: Path, resume: bool, inputs: dict | None = None) -> None:
    """ParameterError if ``out_dir`` cannot take this campaign (touches nothing): it is a file, or it holds a
    campaign and ``resume`` is off, or it holds another spec's campaign, or one flown with other
    ``inputs`` (:func:`campaign_inputs`, checked when given), or ``resume`` is on and it holds no campaign
    (a mistyped path would otherwise start afresh)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ParameterError(f'--out: {out_dir} exists and is not a folder; choose another --out')
    base = out_dir
    while not base.exists() and base != base.parent:
        base = base.parent
    if not base.is_dir():
        raise ParameterError(f'--out: {base} is not a folder, so {out_dir} cannot be created')
    spec_path = out_dir / SPEC_FILE
    if resume and not holds_campaign(out_dir):
        raise ParameterError(f'--resume: {out_dir} holds no campaign to resume (no {FLIGHTS_FILE}); check the path, '
                             'or leave out --resume to start the campaign there')
    if holds_campaign(out_dir):
        if not resume:
            raise ParameterError(f'--out: {out_dir} already holds a campaign; pass --resume (resume=True from '
                                 'Python) to fly only its missing flights, or choose another folder')
        stored = yaml.safe_load(spec_path.read_text()) if spec_path.exists() else None
        if stored != spec.to_mapping():
            raise ParameterError(f'--resume: the campaign in {out_dir} was run with another spec '
                                 f'({spec_path}); resume it with the same spec and overrides')
        if inputs is not None:
            check_inputs(out_dir, inputs)


def prepare_output(spec: CampaignSpec, out_dir: Path, resume: bool, inputs: dict) -> set:
    """Check (and create) the output folder; the (flight, controller) pairs already flown there.

    A folder that already holds a campaign is only continued with ``resume``, and only if its spec
    is the same one (overrides included) and it flew the same vehicle and gains (``inputs``).
    """
    check_output(spec, out_dir, resume, inputs)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not os.access(out_dir, os.W_OK):
        raise ParameterError(f'--out: {out_dir} is not writable')
    (out_dir / SPEC_FILE).write_text(yaml.safe_dump(spec.to_mapping(), sort_keys=False))
    (out_dir / INPUTS_FILE).write_text(yaml.safe_dump(inputs, sort_keys=False))
    return {(r['flight'], r['controller']) for r in read_flights(out_dir / FLIGHTS_FILE)}


def check_main_is_guarded(function: str = 'run_campaign') -> None:
    """ParameterError if the running script calls ``function`` outside ``if __name__ == '__main__':``.

    Local worker processes start with the spawn method, which imports the main script again in each of
    them: an unguarded call would start the campaign again in every worker. Nothing to check when the
    main module has no file (an interactive session, ``python -c``) or is a package's ``__main__``
    (which multiprocessing does not import again), or when the call is not made while the script's
    top level runs.
    """
    main = sys.modules.get('__main__')
    path = getattr(main, '__file__', None)
    name = getattr(getattr(main, '__spec__', None), 'name', None) or ''
    if path is None or name == '__main__' or name.endswith('.__main__'):
        return
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_globals is vars(main) and frame.f_code.co_name == '<module>'):
        frame = frame.f_back
    if frame is None:
        return
    try:
        tree = ast.parse(Path(path).read_text(), path)
    except (OSError, SyntaxError, ValueError):
        return
    if not any(_is_main_guard(node) and node.body[0].lineno <= frame.f_lineno <= node.body[-1].end_lineno
               for node in tree.body):
        raise ParameterError(
            f'{function}: {path} calls it outside `if __name__ == \'__main__\':` (line {frame.f_lineno}); every '
            'local worker process imports that script again as it starts and would run the campaign again. '
            f'Write the call as\n    if __name__ == \'__main__\':\n        {function}(...)')


def _is_main_guard(node: ast.stmt) -> bool:
    """Whether ``node`` is ``if __name__ == '__main__':`` (either way round)."""
    if not isinstance(node, ast.If) or not isinstance(node.test, ast.Compare) or len(node.test.ops) != 1 \
            or not isinstance(node.test.ops[0], ast.Eq):
        return False
    sides = [node.test.left, node.test.comparators[0]]
    return (any(isinstance(side, ast.Name) and side.id == '__name__' for side in sides)
            and any(isinstance(side, ast.Constant) and side.value == '__main__' for side in sides))


@contextlib.contextmanager
def writing(out_dir: Path):
    """Hold the output folder for one run (an exclusive lock on DIR/.campaign.lock, created with the
    folder): a second campaign writing the same folder, such as a ``--resume`` while the first still
    flies, would append the same flights twice; it is refused with ParameterError naming the holder."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise ParameterError(f'--out: {out_dir} cannot be created: a file is in its place') from None
    with FileLock(out_dir / LOCK_FILE,
                  lambda holder: f'--out: another campaign is writing {out_dir} (process {holder}); let it '
                                 'finish, or stop it and continue with --resume (resume=True from Python)'):
        yield


def _ignore_sigint() -> None:
    """Worker processes leave Ctrl-C to the parent, which terminates them."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _started() -> None:
    """A local worker's first task: nothing. Submitting it starts the worker, which then imports the stack (to
    unpickle its initializer) while this process compiles the kernels."""


class _LocalPool:
    def __init__(self, workers: int):
        self.workers = workers
        self.executor = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context('spawn'),
                                            initializer=_ignore_sigint)
        for _ in range(workers):     # one process starts per task submitted while none is idle
            self.executor.submit(_started)
        self.processes = list(self.executor._processes.values())
        #: the executor's thread that reaps the workers once the pool is shut down (shutdown forgets it)
        self.manager = self.executor._executor_manager_thread

    def submit(self, job):
        return self.executor.submit(fly_batch, job)

    @staticmethod
    def wait(futures) -> set:
        """The futures of ``futures`` that are done, once one is (interruptible by a signal)."""
        return wait(futures, return_when=FIRST_COMPLETED).done

    def close(self, cancel: bool) -> None:
        """Tell the workers to exit once their tasks are done (``cancel``: terminate them now); returns at once
        (:meth:`join` waits for them). Closing again does nothing more."""
        if self.executor is None:      # closed with cancel before
            return
        if cancel:
            for process in self.processes:
                process.terminate()
        self.executor.shutdown(wait=False, cancel_futures=cancel)
        if cancel:     # the workers are gone at once: wait for them and free the pool's queues now, whose
            self.join()     # semaphores a stopped command (os._exit) would leave to the resource tracker to
            self.executor = self.manager = None    # warn of ("leaked semaphore objects")
            self.processes = []

    def join(self) -> None:
        """Wait for the closed pool's workers to exit. The executor's manager thread reaps them: waiting on a
        worker beside it races it for the exit status (the loser's join returns with no exit code yet), so
        this waits for that thread first."""
        if self.manager is not None:
            self.manager.join()
        for process in self.processes:
            process.join()


class _DaskPool:
    def __init__(self, address: str):
        try:
            from distributed import Client
        except ImportError as error:     # pragma: no cover - distributed is a pinned dependency
            raise ParameterError('--scheduler needs the distributed package (pip install distributed)') from error
        try:
            self.client = Client(address, timeout='10s', set_as_default=False)
        except (OSError, TimeoutError) as error:
            raise ParameterError(f'--scheduler: cannot reach a Dask scheduler at {address} ({error})') from error

        self.workers = max(1, sum(self.client.nthreads().values()))
        from distributed import as_completed as dask_as_completed
        self.finished = dask_as_completed(loop=self.client.loop)

    def submit(self, job):
        future = self.client.submit(fly_batch, job, pure=False)
        self.finished.add(future)
        return future

    def wait(self, futures) -> set:
        """The next finished future (every future submitted is one of ``futures`` until it is returned)."""
        return {next(self.finished)}

    def close(self, cancel: bool) -> None:
        self.client.close()

    def join(self) -> None:
        """Nothing to wait for: the cluster's workers stay."""


@dataclass
class CampaignOutcome:
    flights_flown: int        #: rows written by this run
    wall_time_s: float
    vehicle_steps: int        #: control steps flown by this run (all vehicles)
    summary_path: Path


def run_campaign(spec: CampaignSpec, out_dir: Path, options: RunOptions) -> CampaignOutcome:
    """Fly every missing flight of ``spec`` into ``out_dir``, then write campaign.json and report.html.

    Raises ParameterError on invalid options (before anything flies or ``out_dir`` is touched) and
    KeyboardInterrupt after stopping the workers on Ctrl-C or SIGTERM (every finished batch is in
    flights.csv). From a script, call it under ``if __name__ == '__main__':`` (local workers import the
    script again; see :func:`check_main_is_guarded`).
    """
    out_dir = Path(out_dir)
    workers = options.worker_count()
    if options.scheduler is None:
        check_main_is_guarded()
    # files, rates and every controller's gains valid before flying
    setup = CampaignSetup.of(spec, options.vehicle_file, options.gains_file)
    setup.check_controllers(spec.controllers)
    inputs = campaign_inputs(spec, setup)
    check_output(spec, out_dir, options.resume, inputs)
    with stop_signals():   # SIGTERM stops it as Ctrl-C does: workers stopped, flights.csv closed
        if options.scheduler is not None:
            with writing(out_dir):
                return _fly_missing(spec, out_dir, options, workers, _DaskPool(options.scheduler), inputs)
        # the local workers start now, and import the stack while the kernels compile here
        pool = _LocalPool(min(workers, max(1, math.ceil(flights_to_fly(spec, set())
                                                        / batch_size(spec, options, workers)))))
        try:
            _compile(spec, options)
            with writing(out_dir):
                return _fly_missing(spec, out_dir, options, workers, pool, inputs)
        finally:
            pool.close(cancel=True)    # after a whole campaign: nothing left to stop


def _compile(spec: CampaignSpec, options: RunOptions) -> None:
    """Compile the kernels (or load them from numba's cache) here, said with the time it took."""
    say = (lambda text, end='\n': print(text, end=end, file=sys.stderr, flush=True)) if options.progress \
        else (lambda text, end='\n': None)
    for kind in map(controller_kind, spec.controllers):
        if not kind.batched:
            say(f'note: {kind.name} steps a batch vehicle by vehicle (it declares no batched update: '
                'docs/CONTROLLERS.md): correct, and slower than a batched kind')
    say('compiling kernels (numba; loaded from its cache after the first time)...', end=' ')
    started = time.perf_counter()
    compile_kernels(spec, options.vehicle_file, options.gains_file)
    say(f'{time.perf_counter() - started:.1f} s (the worker processes load them from the cache)')


def _fly_missing(spec: CampaignSpec, out_dir: Path, options: RunOptions, workers: int, pool,
                 inputs: dict) -> CampaignOutcome:
    """Fly the missing flights on ``pool`` into ``out_dir``, then write the results while its workers exit."""
    done = prepare_output(spec, out_dir, options.resume, inputs)
    total = flights_to_fly(spec, done)
    jobs = plan_jobs(spec, done, options, workers)
    flights = FlightsFile(out_dir / FLIGHTS_FILE, COLUMNS)
    started = time.perf_counter()
    steps = 0
    progress = _progress_bar(total, spec.flights * len(spec.controllers) - total, options.progress,
                             options.progress_label)
    cancelled = False
    try:
        pending: set = set()
        for job in jobs:
            pending.add(pool.submit(job))
            while len(pending) >= QUEUED_PER_WORKER * pool.workers:
                pending, steps = _collect(pool, pending, flights, progress, steps)
        while pending:
            pending, steps = _collect(pool, pending, flights, progress, steps)
    except BaseException:
        cancelled = True
        raise
    finally:
        progress.close()
        flights.close()
        pool.close(cancel=cancelled)
    wall = time.perf_counter() - started
    summary_path = write_results(spec, out_dir, wall_time_s=wall, vehicle_steps=steps, report=options.report)
    pool.join()
    return CampaignOutcome(total, wall, steps, summary_path)


def _collect(pool, pending: set, flights: FlightsFile, progress, steps: int) -> tuple[set, int]:
    """Wait for a batch to finish; append the rows of every finished one. The batches still pending, and
    the control steps flown so far."""
    finished = pool.wait(pending)
    for future in finished:
        rows = future.result()
        flights.append(rows)
        steps += sum(r['control_steps'] for r in rows)
        progress.update(len(rows))
    return pending - finished, steps


def _progress_bar(total: int, already: int, enabled: bool, label: str = 'campaign'):
    from tqdm import tqdm
    return tqdm(total=total + already, initial=already, unit='flight', desc=label, disable=not enabled,
                file=sys.stderr, smoothing=0.1)


def write_results(spec: CampaignSpec, out_dir: Path, wall_time_s: float | None = None,
                  vehicle_steps: int | None = None, report: bool = True) -> Path:
    """campaign.json (and, with ``report``, report.html) from every row of flights.csv."""
    rows = read_flights(out_dir / FLIGHTS_FILE)
    document = {
        'spec': spec.to_mapping(),
        'flights_per_controller': spec.flights,
        'controllers': summarize(rows, spec.controllers),
        'this_run': {'wall_time_s': wall_time_s, 'vehicle_steps': vehicle_steps,
                     'vehicle_steps_per_s': (vehicle_steps / wall_time_s) if wall_time_s else None},
        'notes': ('success = flew the whole duration without a failure (non-finite state, flipped over, '
                  'crashed, position error above max_error_m after settling); percentiles over finished '
                  'flights; success_rate_wilson95 = 95 % Wilson score interval'),
    }
    path = out_dir / SUMMARY_FILE
    path.write_text(json.dumps(document, indent=2) + '\n')
    if report:
        from .report import write_report
        write_report(rows, document, out_dir)
    return path
