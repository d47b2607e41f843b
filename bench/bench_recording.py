#!/usr/bin/env python3
"""What recording a bag costs an embedded flight, and why it is cheap.

1. The same embedded flight without and with recording (create the bag, record every control
   step, close it), alternated ``--repeats`` times; the overhead is taken from the fastest run of
   each kind (the least disturbed by other load on the machine) and also shown for the medians.
2. CDR encoding: the fast per-step encoders against building the message with the conversions
   and ``rosbags`` ``serialize_cdr``, in messages per second.
3. MCAP writing: ``mcap.writer.Writer.add_message`` against ``McapFileWriter.add_message``.

No ROS needed. Usage: python3 bench/bench_recording.py [--duration 60] [--repeats 3]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import timeit
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import flight_stack  # noqa: E402,F401  (puts the package folders on the path)
from flight_stack.embedded import fly_embedded  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge import fast_cdr  # noqa: E402
from quad_msgs_bridge.bag.writer import jazzy_typestore  # noqa: E402
from quad_msgs_bridge.conversions import odometry_msg, rosbags_kit, rotor_forces_msg, wrench_msg  # noqa: E402
from quad_msgs_bridge.bag.flight_bag import FlightBag  # noqa: E402
from quad_msgs_bridge.bag.mcap_file import McapFileWriter  # noqa: E402
from quad_msgs_bridge.state import OdometrySample  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402


def flight_times(duration: float, repeats: int) -> tuple[list[float], list[float], int]:
    params, disturbances = load_vehicle_file(None)
    gains = load_gains(None)
    trajectory = make_scenario('paper', None)

    def fly(bag=None):
        return fly_embedded('nnit2fsmc', trajectory, params, disturbances, gains, duration, 1000.0, bag=bag)

    plain, recorded, steps = [], [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeats):
            plain.append(fly().wall_time_s)
            started = time.perf_counter()
            with FlightBag.create(Path(tmp) / f'bag{k}', params, 5.0, controller='nnit2fsmc') as bag:
                steps = fly(bag).steps
            recorded.append(time.perf_counter() - started)
            print(f'  run {k + 1}: without {plain[-1]:.3f} s, with recording {recorded[-1]:.3f} s', flush=True)
    return plain, recorded, steps


def rate(function, seconds: float = 0.5) -> float:
    """Calls per second of ``function``."""
    count = 1
    while True:
        elapsed = timeit.timeit(function, number=count)
        if elapsed > seconds:
            return count / elapsed
        count *= 4


def encoder_rates() -> list[tuple[str, float, float]]:
    kit, typestore = rosbags_kit(), jazzy_typestore()
    sample = OdometrySample(12.345, (1.0, -2.0, 3.0), (0.1, 0.2, 0.3, 0.927), (0.4, 0.5, 0.6), (0.7, 0.8, 0.9))
    forces, controls = (1.1, 1.2, 1.3, 1.4), (5.0, 0.1, -0.2, 0.01)
    encode_odometry, encode_forces = fast_cdr.odometry_encoder(), fast_cdr.rotor_forces_encoder()
    encode_wrench = fast_cdr.wrench_encoder(0.25)
    return [
        ('nav_msgs/Odometry', rate(lambda: encode_odometry(12, 345000000, sample)),
         rate(lambda: typestore.serialize_cdr(odometry_msg(kit, sample), 'nav_msgs/msg/Odometry'))),
        ('std_msgs/Float64MultiArray (4)', rate(lambda: encode_forces(forces)),
         rate(lambda: typestore.serialize_cdr(rotor_forces_msg(kit, forces), 'std_msgs/msg/Float64MultiArray'))),
        ('geometry_msgs/WrenchStamped', rate(lambda: encode_wrench(12, 345000000, controls)),
         rate(lambda: typestore.serialize_cdr(wrench_msg(kit, 12.345, controls, 0.25),
                                              'geometry_msgs/msg/WrenchStamped'))),
    ]


def writer_costs(count: int = 200_000) -> tuple[float, float]:
    """[us per message] of mcap's Writer.add_message and of McapFileWriter.add_message (700-byte messages)."""
    data = bytes(600) + bytes(range(100))
    with tempfile.TemporaryDirectory() as tmp:
        with open(Path(tmp) / 'a.mcap', 'wb') as stream:
            writer = Writer(stream, compression=CompressionType.ZSTD)
            writer.start('ros2', 'bench')
            channel = writer.register_channel('/t', 'cdr', writer.register_schema('t', 'ros2msg', b''))
            started = time.perf_counter()
            for k in range(count):
                writer.add_message(channel, k, data, k)
            writer.finish()
            mcap_cost = (time.perf_counter() - started) / count
        ours = McapFileWriter(Path(tmp) / 'b.mcap', profile='ros2')
        channel = ours.add_channel('/t', 'cdr', ours.add_schema('t', 'ros2msg', b''), {})
        started = time.perf_counter()
        for k in range(count):
            ours.add_message(channel, k, k, data)
        ours.close()
        our_cost = (time.perf_counter() - started) / count
    return mcap_cost * 1e6, our_cost * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=60.0, help='sim time of the flight [s] (paper: 60)')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()

    print(f'1. embedded paper flight, {args.duration:g} s sim time, NNIT2FSMC, {args.repeats} alternated runs')
    plain, recorded, steps = flight_times(args.duration, args.repeats)
    best = min(recorded) / min(plain) - 1.0
    median = statistics.median(recorded) / statistics.median(plain) - 1.0
    print(f'   without recording: best {min(plain):.3f} s, median {statistics.median(plain):.3f} s')
    print(f'   with recording:    best {min(recorded):.3f} s, median {statistics.median(recorded):.3f} s '
          f'({steps} steps, 6 messages each)')
    print(f'   recording overhead: {100 * best:.1f} % (best runs), {100 * median:.1f} % (medians); '
          f'{1e6 * (min(recorded) - min(plain)) / steps:.1f} us per control step')

    print('2. CDR encoding, messages/s            fast encoder   conversions + rosbags serialize_cdr')
    for name, fast, slow in encoder_rates():
        print(f'   {name:<32} {fast:12,.0f}   {slow:12,.0f}   (x{fast / slow:.0f})')

    mcap_cost, our_cost = writer_costs()
    print(f'3. MCAP writing, us per 700-byte message: mcap Writer.add_message {mcap_cost:.2f}, '
          f'McapFileWriter.add_message {our_cost:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
