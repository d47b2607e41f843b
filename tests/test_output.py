"""The output folder of a run: staged beside its target, moved into place only when complete, nothing
earlier lost (flight_stack.output)."""
import os
import stat

import pytest

from flight_stack.output import STAGING_MARK, RunOutput
from quad_msgs_bridge.validation import ParameterError
from hang_guard import HANG_TIMEOUT_S


def snapshot(folder):
    """{relative path: bytes} of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob('*')) if p.is_file()}


def earlier_run(folder):
    folder.mkdir(parents=True)
    (folder / 'summary.json').write_text('{"old": true}')
    (folder / 'report.html').write_text('old report')
    (folder / 'bag').mkdir()
    (folder / 'bag' / 'metadata.yaml').write_text('old bag')
    (folder / 'notes.txt').write_text('the user\'s own file')
    return snapshot(folder)


def staging_folders(parent):
    return sorted(p.name for p in parent.iterdir() if STAGING_MARK in p.name)


def test_a_new_folder_appears_only_at_commit(tmp_path):
    out = tmp_path / 'runs' / 'first'
    output = RunOutput(out, out / 'bag', overwrite=False)
    assert not (tmp_path / 'runs').exists()          # checking touches nothing
    output.create()
    (output.out / 'summary.json').write_text('new')
    output.bag.mkdir()
    (output.bag / 'bag_0.mcap').write_bytes(b'x')
    assert not out.exists() and output.out.parent == out.parent and STAGING_MARK in output.out.name
    output.commit()
    assert snapshot(out) == {'summary.json': b'new', 'bag/bag_0.mcap': b'x'}
    assert staging_folders(out.parent) == []
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o777 & ~umask    # not the 0700 of a private temporary folder


def test_an_earlier_run_is_refused_without_overwrite_and_untouched(tmp_path):
    out = tmp_path / 'run'
    before = earlier_run(out)
    with pytest.raises(ParameterError, match=r'--out: .* holds an earlier run \(summary.json, report.html, bag\); '
                                             r'pass --overwrite'):
        RunOutput(out, out / 'bag', overwrite=False)
    assert snapshot(out) == before and staging_folders(tmp_path) == []


def test_overwrite_replaces_the_run_files_once_the_run_is_complete(tmp_path):
    out = tmp_path / 'run'
    before = earlier_run(out)
    output = RunOutput(out, None, overwrite=True)
    output.create()
    (output.out / 'summary.json').write_text('new')
    assert snapshot(out) == before                   # still the earlier run while the new one is written
    output.commit()
    # the new run had no bag and no report: the earlier ones go too (they would not match the new summary);
    # the user's own file stays
    assert snapshot(out) == {'summary.json': b'new', 'notes.txt': b"the user's own file"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run']


def test_an_unfinished_run_keeps_what_it_wrote_beside_the_earlier_run(tmp_path):
    out = tmp_path / 'run'
    before = earlier_run(out)
    output = RunOutput(out, out / 'bag', overwrite=True)
    output.create()
    output.bag.mkdir()
    (output.bag / 'bag_0.mcap').write_bytes(b'partial')
    kept = output.keep_partial()
    assert kept == [output.out] and (kept[0] / 'bag' / 'bag_0.mcap').read_bytes() == b'partial'
    assert snapshot(out) == before


def test_an_unfinished_run_that_wrote_nothing_leaves_nothing(tmp_path):
    output = RunOutput(tmp_path / 'run', None, overwrite=False)
    output.create()
    assert output.keep_partial() == []
    assert list(tmp_path.iterdir()) == []


def test_a_bag_outside_the_output_folder_is_a_second_staged_target(tmp_path):
    out, bag = tmp_path / 'run', tmp_path / 'bags' / 'flight1'
    bag.mkdir(parents=True)
    (bag / 'metadata.yaml').write_text('old')
    with pytest.raises(ParameterError, match='--bag: .* exists; pass --overwrite'):
        RunOutput(out, bag, overwrite=False)
    output = RunOutput(out, bag, overwrite=True)
    output.create()
    assert output.bag.name == 'flight1' and output.bag.parent.parent == bag.parent   # the bag keeps its name
    output.bag.mkdir()
    (output.bag / 'flight1_0.mcap').write_bytes(b'new')
    (output.out / 'summary.json').write_text('new')
    assert (bag / 'metadata.yaml').read_text() == 'old'
    output.commit()
    assert snapshot(bag) == {'flight1_0.mcap': b'new'} and snapshot(out) == {'summary.json': b'new'}
    assert staging_folders(bag.parent) == [] and staging_folders(tmp_path) == []


def test_overwrite_never_replaces_a_folder_that_is_not_a_bag(tmp_path):
    home = tmp_path / 'home'
    home.mkdir()
    (home / 'thesis.tex').write_text('precious')
    with pytest.raises(ParameterError, match='is not a bag'):
        RunOutput(tmp_path / 'run', home, overwrite=True)
    with pytest.raises(ParameterError, match='would hold the output folder'):
        RunOutput(tmp_path / 'run', tmp_path, overwrite=True)


@pytest.mark.parametrize('make_parent', ['file', 'sysfs'])
def test_an_unwritable_place_is_refused_before_the_run(tmp_path, make_parent):
    if make_parent == 'file':
        (tmp_path / 'a_file').write_text('')
        out = tmp_path / 'a_file' / 'x'
        with pytest.raises(ParameterError, match='--out: .*a_file is not a directory'):
            RunOutput(out, None, overwrite=False)
        return
    if not os.path.isdir('/sys/kernel'):
        pytest.skip('no sysfs (not Linux): /sys/x is the case of the issue')
    output = RunOutput('/sys/x', None, overwrite=False)   # root may pass the permission check; mkdir fails
    with pytest.raises(ParameterError, match='--out: cannot write into /sys'):
        output.create()



def test_a_bag_of_another_name_in_the_output_folder_belongs_to_the_run(tmp_path):
    out = tmp_path / 'run'
    out.mkdir()
    (out / 'flight7').mkdir()
    (out / 'flight7' / 'metadata.yaml').write_text('old')
    with pytest.raises(ParameterError, match=r'holds an earlier run \(flight7\)'):
        RunOutput(out, out / 'flight7', overwrite=False)
    output = RunOutput(out, out / 'flight7', overwrite=True)
    output.create()
    output.bag.mkdir()
    (output.bag / 'flight7_0.mcap').write_bytes(b'new')
    output.commit()
    assert snapshot(out) == {'flight7/flight7_0.mcap': b'new'}


def test_a_second_run_into_the_same_out_is_refused_while_the_first_writes_it(tmp_path):
    out = tmp_path / 'run'
    first = RunOutput(out, out / 'bag', overwrite=True)
    second = RunOutput(out, out / 'bag', overwrite=True)       # both checked before either started
    first.create()
    with pytest.raises(ParameterError, match=f'--out: another run is writing {out} \\(process {os.getpid()}\\)'):
        second.create()
    (first.out / 'summary.json').write_text('first')
    first.commit()
    assert (out / 'summary.json').read_text() == 'first'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run']      # no staging folder, the lock file is gone
    late = RunOutput(tmp_path / 'run2', None, overwrite=False)
    late.create()
    late.keep_partial()                                                # released on every way out
    again = RunOutput(tmp_path / 'run2', None, overwrite=False)
    again.create()
    again.discard()


def test_a_run_that_finished_while_the_second_waited_is_an_earlier_run_for_it(tmp_path):
    out = tmp_path / 'run'
    first, second = RunOutput(out, None, overwrite=False), RunOutput(out, None, overwrite=False)
    first.create()
    (first.out / 'summary.json').write_text('first')
    first.commit()
    with pytest.raises(ParameterError, match='holds an earlier run'):
        second.create()                     # checked again once it holds the lock
    assert (out / 'summary.json').read_text() == 'first'


@pytest.mark.slow
def test_two_concurrent_flights_into_one_out_neither_is_lost(tmp_path):
    """Two real run_stack.py processes: the second starts while the first writes OUT (its staging folder
    exists) and is refused by name; the first's result is complete in OUT."""
    import subprocess
    import sys
    import time
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    out = tmp_path / 'seed-sweep'
    command = [sys.executable, str(root / 'run_stack.py'), '--backend', 'embedded', '--scenario', 'hover',
               '--duration', '1', '--settle-time', '0.5', '--quiet', '--out', str(out), '--overwrite']
    first = subprocess.Popen(command + ['--seed', '1'], cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    deadline = time.monotonic() + HANG_TIMEOUT_S
    while not staging_folders(tmp_path) and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert staging_folders(tmp_path), 'the first flight never started writing'
    second = subprocess.run(command + ['--seed', '2'], cwd=root, capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    stdout, stderr = first.communicate(timeout=HANG_TIMEOUT_S)
    assert first.returncode in (0, 1), stderr               # flown (1: its checks failed, still a complete run)
    assert second.returncode == 2, second.stderr
    assert f'error: --out: another run is writing {out} (process {first.pid})' in second.stderr, second.stderr
    import json
    assert json.loads((out / 'summary.json').read_text())['seed'] == 1
    assert (out / 'bag' / 'metadata.yaml').exists()
    assert staging_folders(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ['seed-sweep']
