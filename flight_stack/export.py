"""``run_stack.py export BAG --format {csv,parquet} --out FILE``: a recorded flight as a table, one row per
control step, every column named with its unit (``time_s``, ``x_m``, ``vx_mps``, ``phi_rad``, ``U1_N``,
``U4_Nm``, ``S_x_mps``, ``nn_z_N``, ...; see :meth:`~quad_msgs_bridge.review.flight_data.Flight.unit_names`).

The columns are those of :meth:`quad_msgs_bridge.review.flight_data.Flight.columns`: the 12 states as the
odometry gives them (Euler-angle rates ``dphi dtheta dpsi``), the reference, the rotor thrusts F1..F4,
U1..U4 and per subsystem the sliding surface and the NN and fuzzy terms. Parquet needs pyarrow, which
the stack does not install (``pip install pyarrow==25.0.0``, or the ``parquet`` extra).

The file is written beside FILE and moved into place once complete; an existing FILE is replaced only
with ``--overwrite``.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
from pathlib import Path

import numpy as np

FORMATS = ('csv', 'parquet')
PARQUET_HINT = ('--format parquet needs pyarrow, which the flight stack does not install: pip install '
                'pyarrow==25.0.0 (or pip install ".[parquet]"), or export --format csv')


def flight_table(flight) -> dict[str, np.ndarray]:
    """The flight's columns under their names with units (``Flight.unit_names``, as ``Flight.to_pandas`` names
    them), time first (one row per kept step)."""
    names = flight.unit_names()
    return {names[name]: values for name, values in flight.columns().items()}


def write_csv(table: dict[str, np.ndarray], path: Path) -> None:
    """``table`` as CSV: a header of the column names, then one line per row (floats in shortest repr)."""
    with path.open('w', newline='') as file:
        writer = csv.writer(file)
        writer.writerow(table)
        columns = list(table.values())
        for start in range(0, len(columns[0]), 4096):
            writer.writerows(zip(*(column[start:start + 4096].tolist() for column in columns)))


def write_parquet(table: dict[str, np.ndarray], path: Path) -> None:
    """``table`` as a Parquet file (float64 columns). ImportError with :data:`PARQUET_HINT` without pyarrow."""
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError as error:
        raise ImportError(PARQUET_HINT) from error
    pyarrow.parquet.write_table(pyarrow.table({name: np.asarray(values, dtype=float)
                                               for name, values in table.items()}), path)


def read_table(path: Path) -> dict[str, np.ndarray]:
    """A table written by :func:`export_flight` (CSV or Parquet, by its suffix) as float64 columns."""
    path = Path(path)
    if path.suffix == '.parquet':
        try:
            import pyarrow.parquet
        except ImportError as error:
            raise ImportError(PARQUET_HINT) from error
        table = pyarrow.parquet.read_table(path)
        return {name: table.column(name).to_numpy() for name in table.column_names}
    with path.open(newline='') as file:
        reader = csv.reader(file)
        header = next(reader)
        rows = np.array([[float(value) for value in row] for row in reader], dtype=float).reshape(-1, len(header))
    return dict(zip(header, rows.T))


def export_flight(bag: str | Path, out: str | Path, file_format: str | None = None, *, namespace: str | None = None,
                  vehicle_file: str | Path | None = None, overwrite: bool = False) -> Path:
    """Write the flight of ``bag`` (every control step) to ``out`` as ``file_format`` (csv or parquet; None:
    by the suffix of ``out``, else csv); the path written. ValueError (ParameterError, BagReadError) on bad
    input, ImportError without pyarrow for Parquet; both before anything is written."""
    from quad_msgs_bridge.review.flight_from_bag import read_flight
    from quad_msgs_bridge.validation import ParameterError
    out = Path(out)
    file_format = file_format or ('parquet' if out.suffix == '.parquet' else 'csv')
    if file_format not in FORMATS:
        raise ParameterError(f'--format: {file_format!r} is not one of {", ".join(FORMATS)}')
    if out.is_dir():
        raise ParameterError(f'--out: {out} is a folder; give the file to write '
                             f'(e.g. {out / ("flight." + file_format)})')
    if out.exists() and not overwrite:
        raise ParameterError(f'--out: {out} exists; pass --overwrite to replace it, or choose another --out')
    if not out.parent.is_dir():
        raise ParameterError(f'--out: the folder {out.parent} does not exist')
    writer = write_parquet if file_format == 'parquet' else write_csv
    if file_format == 'parquet':
        try:
            import pyarrow.parquet  # noqa: F401  (before reading the bag)
        except ImportError as error:
            raise ImportError(PARQUET_HINT) from error
    table = flight_table(read_flight(bag, namespace=namespace, vehicle_file=vehicle_file, every_step=True))
    partial = out.with_name(f'.{out.name}.incomplete-{os.getpid()}')
    try:
        writer(table, partial)
        os.replace(partial, out)
    finally:
        partial.unlink(missing_ok=True)
    return out


def main(argv: list[str]) -> int:
    from quad_msgs_bridge.output_path import output_path
    parser = argparse.ArgumentParser(prog='run_stack.py export', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory (rosbag2, MCAP or sqlite3) or .mcap file')
    parser.add_argument('--format', choices=FORMATS, default=None,
                        help='file format (default: parquet for an --out ending in .parquet, else csv)')
    parser.add_argument('--out', type=output_path, required=True, help='the file to write')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing --out')
    parser.add_argument('--namespace', default=None, help='vehicle namespace of the topics (default: found; a '
                                                          'fleet\'s bag: one of its vehicles)')
    parser.add_argument('--vehicle', type=Path, default=None,
                        help='vehicle YAML for bags without vehicle parameters (default: the packaged one)')
    args = parser.parse_args(argv)
    try:
        path = export_flight(args.bag, args.out, args.format, namespace=args.namespace, vehicle_file=args.vehicle,
                             overwrite=args.overwrite)
    except (ValueError, ImportError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except OSError as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    print(f'exported: {path}')
    return 0
