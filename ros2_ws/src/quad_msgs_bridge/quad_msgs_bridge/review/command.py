"""review BAG [--compare BAG2 ...]: a recorded flight as numbers and pictures.

Reads any rosbag2 bag (MCAP or sqlite3 storage, or a lone .mcap file) with the contract topics,
computes the metrics of summary.json with the same function as the live summary, prints them, and
writes into the output folder review.json, the plots (plots/*.png, needs matplotlib) and a one-page
report (report.html and report.md) that says what was flown and what each metric means. With
--compare the flights are overlaid in every plot and tabulated side by side.

Run as `ros2 run quad_msgs_bridge review BAG`, `python3 run_stack.py review BAG` or, without ROS,
`python3 -m quad_msgs_bridge.review BAG`.

Exit status: 0 when every flight reviewed is OK, 1 when one of them FAILED (its result line and the
report say why: docs/OUTPUTS.md) or a file could not be written, 2 when a path is not a readable bag or
an option is invalid.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

from quad_msgs_bridge.output_path import output_path
from quad_msgs_bridge.review.flight_from_bag import BagFlight, fleet_namespaces, read_flight
from quad_msgs_bridge.review.plots import plot_flights
from quad_msgs_bridge.review.report import text_table, write_html, write_markdown
from quad_msgs_bridge.review.summary import flight_summary, recorded_vehicle
from quad_msgs_bridge.review.verdict import max_error_of, planned_duration

#: what a review writes into its output folder
REVIEW_FILES = ('review.json', 'report.md', 'report.html', 'plots')
PLOT_HINT = ('plots skipped: matplotlib is not installed (pip install matplotlib, '
             'or sudo apt install python3-matplotlib)')


@dataclass
class Review:
    flights: list[BagFlight]
    metrics: list[dict]
    out_dir: Path
    report: Path                      #: report.html
    plots: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _unique_labels(flights: Sequence[BagFlight]) -> list[str]:
    labels = [f.label for f in flights]
    return [f'{label} ({f.path.name})' if labels.count(label) > 1 else label for label, f in zip(labels, flights)]


def review_bags(bags: Sequence[str | Path], out_dir: str | Path, *, namespace: str | None = None,
                vehicle_file: str | Path | None = None, settle_time: float | None = None,
                plots: bool = True) -> Review:
    """Metrics, plots and report of ``bags`` (several: compared) into ``out_dir``.

    The bag of a fleet (custom data ``vehicles``) gives one flight per vehicle, labelled by its
    namespace, unless ``namespace`` picks one.
    """
    flights = []
    for bag in bags:
        vehicles = fleet_namespaces(bag) if namespace is None else []
        for vehicle in vehicles or [namespace]:
            flight = read_flight(bag, namespace=vehicle, vehicle_file=vehicle_file, settle_time=settle_time)
            if vehicles:
                flight.label = vehicle
            flights.append(flight)
    return review_flights(flights, out_dir, plots=plots)


def with_failure(metrics: dict, flight: BagFlight) -> dict:
    """``metrics`` with the flight's verdict as ``summary.json`` has it (quad_msgs_bridge.review.verdict):
    ``failure`` (why a failure rule stopped it, None if none did, as far as its bag records) and
    ``failure_time_s`` [s, sim time], ``ended_early`` (why and where it ended before its planned length,
    None if it did not), ``planned_duration_s`` (None: not recorded), ``failures`` and ``flight_ok``; and
    ``vehicle``, its name."""
    failure, custom = flight.failure, flight.custom_data
    return flight_summary(metrics, ended=flight.ending, max_error=max_error_of(custom),
                          failure=None if failure is None else failure[0],
                          failure_time_s=None if failure is None else failure[1],
                          planned_duration_s=planned_duration(custom), vehicle=recorded_vehicle(flight))


def failure_note(label: str, metrics: dict) -> str:
    """What the report says of a failed flight: why, and for one that ended early what its metrics cover."""
    covered = ('' if metrics['ended_early'] is None
               else '; its metrics: NaN: it failed before the settling window ended'
               if math.isnan(metrics['rmse_position_m'])
               else f'; its metrics: they cover the {metrics["duration_s"]:.3f} s it flew')
    return f'{label} FAILED: {"; ".join(metrics["failures"])}{covered}'


def review_flights(flights: Sequence[BagFlight], out_dir: str | Path, *, plots: bool = True) -> Review:
    """Metrics, plots and report of ``flights`` (several: compared) into ``out_dir``.

    A flight just flown is reviewed from its record in memory, a recorded one from its bag
    (:func:`review_bags`): the same metrics either way.
    """
    out_dir = Path(out_dir)
    for flight, label in zip(flights, _unique_labels(flights)):
        flight.label = label
    metrics = [with_failure(flight.metrics(), flight) for flight in flights]
    notes = [f'{f.label}: {warning}' for f in flights for warning in f.warnings]
    notes += [failure_note(f.label, m) for f, m in zip(flights, metrics) if m['failures']]
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / 'review.json').write_text(json.dumps(
        [{'label': f.label, 'bag': str(f.path), **m} for f, m in zip(flights, metrics)], indent=2) + '\n')
    plot_paths: list[Path] = []
    if plots:
        try:
            plot_paths = plot_flights(flights, out_dir / 'plots')
        except ImportError:
            notes.append(PLOT_HINT)
    write_markdown(out_dir / 'report.md', flights, metrics, plot_paths, notes)
    report = write_html(out_dir / 'report.html', flights, metrics, plot_paths, notes)
    return Review(list(flights), metrics, out_dir, report, plot_paths, notes)


def clear_earlier_review(out_dir: Path, overwrite: bool) -> None:
    """Make room for a review in ``out_dir``: ValueError if it holds an earlier review or run and not
    ``overwrite``; with it, the earlier review's plots go (so none of them is taken for the new review's)."""
    earlier = [name for name in (*REVIEW_FILES, 'summary.json') if (out_dir / name).exists()]
    if not earlier:
        return
    if not overwrite:
        raise ValueError(f'--out: {out_dir} holds an earlier review or run ({", ".join(earlier)}); pass --overwrite '
                         'to replace its review, or choose another --out')
    plots = out_dir / 'plots'
    if plots.is_dir():
        for plot in plots.glob('*.png'):
            plot.unlink()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='review', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory (rosbag2, MCAP or sqlite3) or .mcap file')
    parser.add_argument('--compare', type=Path, nargs='+', default=[], metavar='BAG',
                        help='more bags to overlay and tabulate next to the first')
    parser.add_argument('--out', type=output_path, default=None,
                        help='output folder (default: BAG-review next to BAG); one that holds an earlier review or '
                             'run is refused without --overwrite')
    parser.add_argument('--overwrite', action='store_true',
                        help='replace the earlier review in --out (its review.json, report.md, report.html and '
                             'plots/; a run\'s summary.json and bag stay)')
    parser.add_argument('--vehicle', type=Path, default=None,
                        help='vehicle YAML for bags without vehicle parameters (default: the packaged one)')
    parser.add_argument('--settle-time', type=float, default=None,
                        help='metrics ignore the first S seconds (default: as recorded, else 5, or half of a '
                             'flight shorter than 10 s)')
    parser.add_argument('--namespace', default=None, help='vehicle namespace of the topics (default: found)')
    parser.add_argument('--no-plots', action='store_true', help='metrics and report only')
    args = parser.parse_args(argv)
    out_dir = args.out or args.bag.parent / f'{args.bag.name}-review'
    try:
        clear_earlier_review(out_dir, args.overwrite)
        result = review_bags([args.bag, *args.compare], out_dir, namespace=args.namespace,
                             vehicle_file=args.vehicle, settle_time=args.settle_time, plots=not args.no_plots)
    except (ValueError, OSError) as error:   # ValueError (BagReadError, ParameterError, too short): wrong input
        print(f'error: {error}', file=sys.stderr)
        return 2 if isinstance(error, ValueError) else 1
    print(text_table([f.label for f in result.flights], result.metrics))
    for note in result.notes:
        print(f'note: {note}')
    print(f'report: {result.report}' + (f' ({len(result.plots)} plots in {result.plots[0].parent})'
                                         if result.plots else ''))
    return 0 if all(metrics['flight_ok'] for metrics in result.metrics) else 1


if __name__ == '__main__':
    sys.exit(main())
