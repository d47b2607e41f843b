#!/usr/bin/env python3
"""What the live view (run_stack.py --live, as fast as possible: --speed-factor 0) costs an embedded flight.

The same recorded embedded flight (bag on in every case), alternated ``--repeats`` times:

1. without the live view;
2. with the live view and no client;
3. with the live view and a client subscribed to every channel (another process, as the Foxglove
   app would be, reading everything it is sent).

The flight's wall time (the control loop, with its bag writes and live-view calls) is printed per
run, then the medians and the fastest runs side by side, as ratios to case 1. Then the flight
thread's own cost per control step: ``LiveView.record_step`` without a client, and the contract
messages it makes (encoding and handing them to the server) when a client is subscribed. No ROS needed.

Usage: python3 bench/bench_live_view.py [--duration 10] [--repeats 3]
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import flight_stack  # noqa: E402,F401  (puts the package folders on the path)
from flight_stack.embedded import fly_embedded  # noqa: E402
from flight_stack.live_view import SUBPROTOCOL, serve_live_view  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.bag.flight_bag import FlightBag  # noqa: E402
from quad_msgs_bridge.state import OdometrySample  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402


def client(url: str) -> None:
    """Subscribe to every advertised channel, read until the server goes away, print what came."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect
    count = size = 0
    with connect(url, subprotocols=[SUBPROTOCOL], max_size=None) as ws:
        channels = []
        while True:
            message = json.loads(ws.recv(timeout=10))
            if message['op'] == 'advertise':
                channels = message['channels']
                break
        ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': c['id'], 'channelId': c['id']}
                                                                 for c in channels]}))
        print('subscribed', flush=True)
        try:
            while True:
                frame = ws.recv()
                count, size = count + 1, size + len(frame)
        except ConnectionClosed:
            pass
    print(f'received {count} frames, {size / 1e6:.1f} MB', flush=True)


def flight_times(duration: float, repeats: int) -> dict[str, list[float]]:
    params, disturbances = load_vehicle_file(None)
    gains = load_gains(None)
    trajectory = make_scenario('paper', None)
    times: dict[str, list[float]] = {'without live view': [], 'live view, no client': [],
                                     'live view, client on every channel': []}

    def fly(bag_dir: Path, sinks=()) -> float:
        with FlightBag.create(bag_dir, params, 5.0, controller='nnit2fsmc') as bag:
            result = fly_embedded('nnit2fsmc', trajectory, params, disturbances, gains, duration, 1000.0,
                                  bag=bag, sinks=sinks)
        for sink in sinks:
            sink.close()
        return result.wall_time_s

    with tempfile.TemporaryDirectory() as tmp:
        for k in range(repeats):
            plain, alone, watched = times.values()
            plain.append(fly(Path(tmp) / f'plain{k}'))
            view = serve_live_view('127.0.0.1', 0, params)
            with view.server:
                alone.append(fly(Path(tmp) / f'alone{k}', [view]))
            view = serve_live_view('127.0.0.1', 0, params)
            with view.server:
                reader = subprocess.Popen([sys.executable, __file__, '--client', view.server.url],
                                          stdout=subprocess.PIPE, text=True)
                assert reader.stdout.readline().strip() == 'subscribed'
                time.sleep(0.5)                   # the server has taken every subscription
                watched.append(fly(Path(tmp) / f'watched{k}', [view]))
            received = reader.communicate(timeout=60)[0].strip()
            print(f'  run {k + 1}: ' + ', '.join(f'{name} {values[-1]:.3f} s' for name, values in times.items())
                  + f' (client: {received})', flush=True)
    return times


def per_step_costs(number: int = 20000) -> tuple[float, float]:
    """[us] of LiveView.record_step without a client, and of the contract messages of one step."""
    params, _ = load_vehicle_file(None)
    sample = OdometrySample(12.345, (1.0, -2.0, 3.0), (0.1, 0.2, 0.3, 0.927), (0.4, 0.5, 0.6), (0.7, 0.8, 0.9))
    step = (sample, (1.1, 1.2, 1.3, 1.4), (5.0, 0.1, -0.2, 0.01), (1.0, 2.0, 3.0), 0.1, [0.1] * 6, [0.2] * 6,
            [0.3] * 6, [3.0] * 6)
    view = serve_live_view('127.0.0.1', 0, params)
    with view.server:
        alone = timeit.timeit(lambda: view.record_step(*step), number=number)
        messages = timeit.timeit(lambda: view._contract.record_step(*step), number=number)
    return 1e6 * alone / number, 1e6 * messages / number


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=10.0, help='sim time per flight [s] (1000 steps/s)')
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--client', metavar='URL', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        client(args.client)
        return 0
    print(f'embedded flight, {args.duration:g} s sim, recorded; live view as fast as possible '
          f'({args.repeats} runs of each, alternated)')
    times = flight_times(args.duration, args.repeats)
    base_median, base_min = statistics.median(times['without live view']), min(times['without live view'])
    print(f'{"":36s} {"median [s]":>10s} {"ratio":>7s} {"fastest [s]":>11s} {"ratio":>7s}')
    for name, values in times.items():
        median, fastest = statistics.median(values), min(values)
        print(f'{name:36s} {median:10.3f} {median / base_median:7.3f} {fastest:11.3f} {fastest / base_min:7.3f}')
    steps = round(args.duration * 1000)
    alone, messages = per_step_costs()
    print(f'per control step: the flight without live view {1e6 * base_median / steps:.0f} us (median); '
          f'LiveView.record_step without a client {alone:.1f} us; the contract messages for a client {messages:.1f} us')
    return 0


if __name__ == '__main__':
    sys.exit(main())
