"""The bag writer: clear errors (unwritable path, existing bag, full disk), the queued writer thread,
finished chunks on disk while recording, and `recover` of a truncated bag."""
import errno
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from quad_msgs_bridge.bag import mcap_file
from quad_msgs_bridge.bag.metadata import read_metadata
from quad_msgs_bridge.bag.reader import BagReadError, McapPrefix, is_finalized
from quad_msgs_bridge.bag.recover import recover, recover_main
from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import CLOCK, ODOM
from quad_msgs_bridge.fast_cdr import clock_encoder, odometry_encoder
from quad_msgs_bridge.bag.mcap_file import BagWriteError, McapFileWriter
from quad_msgs_bridge.state import OdometrySample

TOPICS = (ODOM, CLOCK)
ENCODE_CLOCK, ENCODE_ODOMETRY = clock_encoder(), odometry_encoder()


def sample_messages(count: int):
    """(topic, CDR, log time [ns]) of ``count`` steps of odometry and clock at 1 kHz."""
    for k in range(count):
        sec, nanosec = divmod(k * 1_000_000, 1_000_000_000)
        sample = OdometrySample(k * 1e-3, (k * 1e-3, 1.0, 2.0), (0.0, 0.0, 0.0, 1.0), (0.1, 0.2, k), (0.0, 0.0, 0.0))
        yield '/clock', ENCODE_CLOCK(sec, nanosec), k * 1_000_000
        yield '/quad/odom', ENCODE_ODOMETRY(sec, nanosec, sample), k * 1_000_000


def record(path, steps: int, **options) -> BagWriter:
    with BagWriter(path, TOPICS, 'quad', **options) as writer:
        for topic, data, stamp in sample_messages(steps):
            writer.write_serialized(topic, data, stamp)
    return writer


def read_back(bag) -> list[tuple]:
    with AnyReader([bag]) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


# --- errors -----------------------------------------------------------------------------------

def test_an_unwritable_path_is_a_clear_error_naming_it(tmp_path):
    blocker = tmp_path / 'a_file'
    blocker.write_text('not a directory')
    with pytest.raises(BagWriteError, match='cannot create bag directory') as error:
        BagWriter(blocker / 'bag', TOPICS)
    assert str(blocker / 'bag') in str(error.value)


NOBODY = 65534


def outcome_unprivileged(call) -> str:
    """What ``call()`` raised (``'TypeName: message'``, or ``'no error'``), run in a forked child that
    drops root privileges first: root writes into read-only directories, an ordinary user does not."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        try:
            if os.geteuid() == 0:
                os.setgid(NOBODY)
                os.setuid(NOBODY)
            call()
            outcome = 'no error'
        except BaseException as error:
            outcome = f'{type(error).__name__}: {error}'
        os.write(write, outcome.encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as pipe:
        outcome = pipe.read()
    os.waitpid(pid, 0)
    return outcome


def test_a_read_only_directory_is_a_clear_error():
    read_only = Path(tempfile.mkdtemp())     # under /tmp: reachable by the unprivileged child
    read_only.chmod(0o555)
    try:
        outcome = outcome_unprivileged(lambda: BagWriter(read_only / 'bag', TOPICS))
    finally:
        read_only.chmod(0o700)
        shutil.rmtree(read_only)
    assert outcome.startswith('BagWriteError') and 'Permission denied' in outcome
    assert str(read_only / 'bag') in outcome


def test_an_existing_bag_is_replaced_only_with_overwrite(tmp_path):
    record(tmp_path / 'bag', 5)
    with pytest.raises(BagWriteError, match='not empty'):
        BagWriter(tmp_path / 'bag', TOPICS)
    record(tmp_path / 'bag', 7, overwrite=True)
    assert len(read_back(tmp_path / 'bag')) == 14
    (tmp_path / 'other').mkdir()
    (tmp_path / 'other' / 'notes.txt').write_text('keep me')
    with pytest.raises(BagWriteError, match='nor a bag'):
        BagWriter(tmp_path / 'other', TOPICS, overwrite=True)
    assert (tmp_path / 'other' / 'notes.txt').read_text() == 'keep me'


@pytest.mark.skipif(not os.path.exists('/dev/full'), reason='no /dev/full')
def test_a_full_device_is_a_clear_error():
    writer = McapFileWriter('/dev/full', profile='ros2')
    with pytest.raises(BagWriteError) as error:
        writer.flush()
    assert error.value.errno == errno.ENOSPC and '/dev/full' in str(error.value)


class FillingDisk:
    """A file that accepts ``capacity`` bytes, then fails like a full disk."""

    def __init__(self, path, capacity: int):
        self.file, self.capacity = open(path, 'wb'), capacity

    def write(self, data) -> int:
        if self.file.tell() + len(data) > self.capacity:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return self.file.write(data)

    def flush(self) -> None:
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def test_a_disk_filling_up_while_recording_is_a_clear_error_not_a_hang(tmp_path, monkeypatch):
    monkeypatch.setattr(mcap_file, 'open', lambda path, mode: FillingDisk(path, 50_000), raising=False)
    writer = BagWriter(tmp_path / 'bag', TOPICS, chunk_size=32 * 1024)
    raised = []
    try:
        for topic, data, stamp in sample_messages(5000):
            writer.write_serialized(topic, data, stamp)
    except BagWriteError as error:
        raised.append(error)
    assert raised, 'writing to a full disk raised nothing'
    with pytest.raises(BagWriteError) as error:
        writer.close()
    assert error.value.errno == errno.ENOSPC
    assert all(earlier is error.value for earlier in raised)     # the same failure, reported again on close
    assert str(tmp_path / 'bag' / 'bag_0.mcap') in str(error.value)
    writer.close()                  # closed once and for all
    prefix = McapPrefix(tmp_path / 'bag' / 'bag_0.mcap')
    assert sum(1 for _ in prefix.records()) > 100 and not prefix.complete   # readable up to the last chunk


# --- what a recorder adds before closing ------------------------------------------------------------

def test_custom_data_added_before_close_is_in_the_final_metadata(tmp_path):
    writer = BagWriter(tmp_path / 'bag', TOPICS, custom_data={'controller': 'pid'})
    for message in sample_messages(10):
        writer.write_serialized(*message)
    writer.custom_data['lost_messages'] = '3'
    writer.close()
    information = read_metadata(tmp_path / 'bag')
    assert information['message_count'] == 20
    assert information['custom_data'] == {'controller': 'pid', 'lost_messages': '3'}


# --- durability ------------------------------------------------------------------------------------

def test_finished_chunks_are_on_disk_while_recording(tmp_path):
    """What a SIGKILL would lose is bounded: the open chunk and the one being written (memory bound too)."""
    chunk_size = 32 * 1024
    writer = BagWriter(tmp_path / 'bag', TOPICS, chunk_size=chunk_size)
    written = 0
    for topic, data, stamp in sample_messages(1500):
        writer.write_serialized(topic, data, stamp)
        written += 1
    prefix = McapPrefix(tmp_path / 'bag' / 'bag_0.mcap')
    on_disk = sum(1 for record in prefix.records() if type(record).__name__ == 'Message')
    smallest_record = 22 + len(ENCODE_CLOCK(0, 0))
    assert written - 2 * chunk_size // smallest_record <= on_disk < written
    assert not prefix.complete
    assert read_metadata(tmp_path / 'bag')['topics_with_message_count']   # a recognisable bag already
    writer.close()


# --- recover -----------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def finished_bag(tmp_path_factory):
    bag = tmp_path_factory.mktemp('recover') / 'bag'
    record(bag, 2000, chunk_size=16 * 1024, custom_data={'controller': 'test'})
    return bag


@pytest.mark.parametrize('fraction', [0.1, 0.5, 0.9, 0.999])
def test_recover_keeps_every_complete_chunk_of_a_cut_bag(finished_bag, tmp_path, fraction):
    bag = tmp_path / 'bag'
    shutil.copytree(finished_bag, bag)
    storage = bag / 'bag_0.mcap'
    os.truncate(storage, int(storage.stat().st_size * fraction))
    assert not is_finalized(storage)
    prefix = McapPrefix(storage)
    readable = sum(1 for record in prefix.records() if type(record).__name__ == 'Message')
    assert readable > 0
    assert recover_main([str(bag)]) == 0
    assert is_finalized(storage)
    recovered = read_back(bag)
    assert len(recovered) == readable
    assert recovered == read_back(finished_bag)[:readable]          # the first messages, unchanged
    information = read_metadata(bag)
    assert information['message_count'] == readable
    assert sum(t['message_count'] for t in information['topics_with_message_count']) == readable
    assert information['custom_data'] == {'controller': 'test'}
    assert not list(bag.glob('*.killed'))


def test_recover_refuses_a_finalized_bag_and_a_headless_file(finished_bag, tmp_path):
    with pytest.raises(BagReadError, match='already finalized'):
        recover(finished_bag)
    bag = tmp_path / 'bag'
    shutil.copytree(finished_bag, bag)
    os.truncate(bag / 'bag_0.mcap', 12)
    with pytest.raises(BagReadError, match='no MCAP header'):
        recover(bag)
    assert (bag / 'bag_0.mcap').stat().st_size == 12      # the original is left as it was
