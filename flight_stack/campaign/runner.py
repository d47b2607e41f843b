"""Running a campaign: batches on local worker processes or on a Dask cluster, results streamed to disk.

A campaign is a list of independent :class:`~.batch.BatchJob` (one controller, up to
``batch_size`` flights). Local runs use a process pool (one process per worker, default: every
core); with a scheduler address the jobs go to an existing Dask distributed cluster (``dask
scheduler`` / ``dask worker``; a scheduler runs whatever code it is sent: use it on a trusted
network only). Every finished batch is appended to ``flights.csv`` at once, so Ctrl-C or a crash
loses no finished batch, and ``resume`` flies only the missing (flight, controller) pairs.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import math
import multiprocessing
import os
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import yaml

from quad_msgs_bridge.vehicle_params import ParameterError

from .batch import COLUMNS, BatchJob, CampaignSetup, fly_batch
from .results import FLIGHTS_FILE, SUMMARY_FILE, FlightsFile, read_flights, summarize
from .spec import CampaignSpec

SPEC_FILE = 'spec.yaml'
LOCK_FILE = '.campaign.lock'


@dataclass(frozen=True)
class RunOptions:
    workers: int | None = None          #: local processes (default: every core)
    batch_size: int | None = None       #: flights per batch (default: an even share per worker, at most 500)
    scheduler: str | None = None        #: Dask scheduler address, e.g. tcp://127.0.0.1:8786
    resume: bool = False
    progress: bool = True
    vehicle_file: str | None = None
    gains_file: str | None = None

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


def plan_jobs(spec: CampaignSpec, done: set, options: RunOptions, workers: int) -> list[BatchJob]:
    """The batches still to fly: for each controller, its missing flights in chunks of the batch size."""
    size = options.batch_size or max(1, min(500, math.ceil(spec.flights / workers)))
    jobs = []
    for controller in spec.controllers:
        missing = [k for k in range(spec.flights) if (k, controller) not in done]
        for start in range(0, len(missing), size):
            jobs.append(BatchJob(spec, controller, tuple(missing[start:start + size]),
                                 options.vehicle_file, options.gains_file))
    return jobs


def prepare_output(spec: CampaignSpec, out_dir: Path, resume: bool) -> set:
    """Check (and create) the output folder; the (flight, controller) pairs already flown there.

    A folder that already holds a campaign is only continued with ``resume``, and only if its spec
    is the same one (overrides included).
    """
    flights_path, spec_path = out_dir / FLIGHTS_FILE, out_dir / SPEC_FILE
    document = spec.to_mapping()
    if flights_path.exists() or spec_path.exists():
        if not resume:
            raise ParameterError(f'--out: {out_dir} already holds a campaign; pass --resume to fly only its '
                                 'missing flights, or choose another folder')
        stored = yaml.safe_load(spec_path.read_text()) if spec_path.exists() else None
        if stored != document:
            raise ParameterError(f'--resume: the campaign in {out_dir} was run with another spec '
                                 f'({spec_path}); resume it with the same spec and overrides')
    out_dir.mkdir(parents=True, exist_ok=True)
    if not os.access(out_dir, os.W_OK):
        raise ParameterError(f'--out: {out_dir} is not writable')
    spec_path.write_text(yaml.safe_dump(document, sort_keys=False))
    return {(r['flight'], r['controller']) for r in read_flights(flights_path)}


@contextlib.contextmanager
def writing(out_dir: Path):
    """Hold the output folder for one run (an exclusive lock on DIR/.campaign.lock, created with the
    folder): a second campaign writing the same folder, such as a ``--resume`` while the first still
    flies, would append the same flights twice; it is refused with ParameterError naming the holder."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / LOCK_FILE
    with open(path, 'a+') as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.seek(0)
            raise ParameterError(f'--out: another campaign is writing {out_dir} (process {lock.read().strip()}); '
                                 'let it finish, or stop it and continue with --resume') from None
        lock.truncate(0)
        lock.write(f'{os.getpid()}\n')
        lock.flush()
        try:
            yield
        finally:
            path.unlink(missing_ok=True)   # still held: no other run took it in between


def _ignore_sigint() -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them between batches."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


class _LocalPool:
    def __init__(self, workers: int):
        self.executor = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context('spawn'),
                                            initializer=_ignore_sigint)

    def submit(self, job):
        return self.executor.submit(fly_batch, job)

    @staticmethod
    def as_completed(futures):
        return as_completed(futures)

    def close(self, cancel: bool) -> None:
        if cancel:
            for process in list(getattr(self.executor, '_processes', {}).values()):
                process.terminate()
        self.executor.shutdown(wait=not cancel, cancel_futures=cancel)


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

    def submit(self, job):
        return self.client.submit(fly_batch, job, pure=False)

    def as_completed(self, futures):
        from distributed import as_completed as dask_as_completed
        return dask_as_completed(futures, loop=self.client.loop)

    def close(self, cancel: bool) -> None:
        self.client.close()


@dataclass
class CampaignOutcome:
    flights_flown: int        #: rows written by this run
    wall_time_s: float
    vehicle_steps: int        #: control steps flown by this run (all vehicles)
    summary_path: Path


def run_campaign(spec: CampaignSpec, out_dir: Path, options: RunOptions) -> CampaignOutcome:
    """Fly every missing flight of ``spec`` into ``out_dir``, then write campaign.json and report.html.

    Raises ParameterError on invalid options (before anything flies) and KeyboardInterrupt after
    stopping the workers on Ctrl-C (every finished batch is in flights.csv).
    """
    workers = options.worker_count()
    # files, rates and every controller's gains valid before flying
    CampaignSetup.of(spec, options.vehicle_file, options.gains_file).check_controllers(spec.controllers)
    with writing(out_dir):
        return _fly_missing(spec, out_dir, options, workers)


def _fly_missing(spec: CampaignSpec, out_dir: Path, options: RunOptions, workers: int) -> CampaignOutcome:
    done = prepare_output(spec, out_dir, options.resume)
    jobs = plan_jobs(spec, done, options, workers)
    total = sum(len(job.flights) for job in jobs)
    flights = FlightsFile(out_dir / FLIGHTS_FILE, COLUMNS)
    started = time.perf_counter()
    steps = 0
    progress = _progress_bar(total, len(done), options.progress)
    pool = _DaskPool(options.scheduler) if options.scheduler else _LocalPool(min(workers, max(1, len(jobs))))
    cancelled = False
    try:
        for future in pool.as_completed([pool.submit(job) for job in jobs]):
            rows = future.result()
            flights.append(rows)
            steps += sum(r['control_steps'] for r in rows)
            progress.update(len(rows))
    except BaseException:
        cancelled = True
        raise
    finally:
        progress.close()
        flights.close()
        pool.close(cancel=cancelled)
    wall = time.perf_counter() - started
    summary_path = write_results(spec, out_dir, wall_time_s=wall, vehicle_steps=steps)
    return CampaignOutcome(total, wall, steps, summary_path)


def _progress_bar(total: int, already: int, enabled: bool):
    from tqdm import tqdm
    return tqdm(total=total + already, initial=already, unit='flight', desc='campaign', disable=not enabled,
                file=sys.stderr, smoothing=0.1)


def write_results(spec: CampaignSpec, out_dir: Path, wall_time_s: float | None = None,
                  vehicle_steps: int | None = None) -> Path:
    """campaign.json (and report.html) from every row of flights.csv."""
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
    from .report import write_report
    write_report(rows, document, out_dir)
    return path
