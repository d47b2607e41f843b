"""Nothing lost: run_stack.py recording a flight is stopped by SIGINT/SIGTERM (bag finalized) or
killed by SIGKILL (bag readable up to its last chunk, then finalized by `recover`)."""
import os
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap.records import Message
from rosbags.highlevel import AnyReader

from quad_msgs_bridge.bag.metadata import read_metadata
from quad_msgs_bridge.bag.reader import McapPrefix, is_finalized, mcap_file
from quad_msgs_bridge.review.command import review_bags
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
STARTUP_TIMEOUT = HANG_TIMEOUT_S   #: [s] for the flight to start recording: only a hang takes that long


def start_flight(out: Path) -> subprocess.Popen:
    """run_stack.py flying the 60 s paper flight with recording, in its own process group."""
    return subprocess.Popen([sys.executable, str(ROOT / 'run_stack.py'), '--backend', 'embedded', '--quiet',
                             '--out', str(out)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def wait_for_chunks(process: subprocess.Popen, out: Path, size: int = 600_000) -> Path:
    """Wait until the bag being recorded (in the run's staging folder beside ``out``) holds a few compressed
    chunks; returns the bag."""
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while True:
        staged = list(out.parent.glob(f'{out.name}.incomplete-*/bag/bag_0.mcap'))
        if staged and staged[0].stat().st_size > size:
            return staged[0].parent
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, 'the flight did not start recording'
        time.sleep(0.05)


def counts_read_back(bag: Path) -> dict:
    with AnyReader([bag]) as reader:
        counts = {c.topic: 0 for c in reader.connections}
        for connection, _, _ in reader.messages():
            counts[connection.topic] += 1
    return counts


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM])
def test_sigint_or_sigterm_finalizes_the_bag(tmp_path, stop):
    out = tmp_path / 'run'
    process = start_flight(out)
    bag = wait_for_chunks(process, out)
    storage = bag / 'bag_0.mcap'
    process.send_signal(stop)
    _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
    assert process.returncode == 130
    assert f'interrupted; bag closed: {bag}' in stderr and f'the unfinished run stays in {bag.parent}' in stderr
    assert is_finalized(storage)
    counts = counts_read_back(bag)
    information = read_metadata(bag)
    assert {t['topic_metadata']['name']: t['message_count'] for t in information['topics_with_message_count']} \
        == counts
    assert information['message_count'] == sum(counts.values()) > 3000
    per_step = [n for topic, n in counts.items()
                if not topic.endswith(('setpoints', 'reference_path', 'robot_description', '/tf_static'))]
    assert max(per_step) == min(per_step)              # stopped between two control steps
    assert not out.exists() and not (bag.parent / 'summary.json').exists()   # an interrupted flight has no summary


def test_sigkill_leaves_a_readable_prefix_that_recover_finalizes(tmp_path):
    out = tmp_path / 'run'
    process = start_flight(out)
    bag = wait_for_chunks(process, out)
    storage = bag / 'bag_0.mcap'
    os.killpg(process.pid, signal.SIGKILL)
    process.communicate(timeout=HANG_TIMEOUT_S)
    assert not is_finalized(storage)
    assert read_metadata(bag)['storage_identifier'] == 'mcap'     # written at the start: still a bag

    prefix = McapPrefix(storage)
    messages = [r for r in prefix.records() if isinstance(r, Message)]
    assert len(messages) > 3000 and not prefix.complete
    # mcap's own stream reader reads the same messages, then fails on the cut-off tail
    direct = []
    with open(storage, 'rb') as stream:
        with pytest.raises((McapError, struct.error)):   # EndOfFile, or a record head cut in two
            for _, _, message in NonSeekingReader(stream, validate_crcs=True).iter_messages(log_time_order=False):
                direct.append(message)
    assert [(m.channel_id, m.log_time, m.data) for m in direct[:len(messages)]] == \
        [(m.channel_id, m.log_time, m.data) for m in messages]

    recovered = subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), 'recover', str(bag)], cwd=ROOT,
                               capture_output=True, text=True, check=True)
    assert f'recovered {len(messages)} messages' in recovered.stdout
    assert is_finalized(mcap_file(bag))
    counts = counts_read_back(bag)
    assert sum(counts.values()) == len(messages) == read_metadata(bag)['message_count']
    review = review_bags([bag], tmp_path / 'review', settle_time=0.5, plots=False)
    assert review.metrics[0]['control_steps'] >= min(counts.values()) - 1
