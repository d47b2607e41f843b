"""Compiled kernels are never served stale from numba's cache (issue 21, quad_msgs_bridge.kernel_cache).

The end-to-end test edits it2_fuzzy.py in a copy of the packages whose kernels are already cached and
checks that the NNIT2FSMC law, which inlines the fuzzy term, uses the edit at once; on the tree before
kernel_cache it kept the cached, old law."""
import ast
import importlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from numba.core import caching
from numba.core.caching import NullCache
from numba.core.registry import CPUDispatcher

from nnit2fsmc_controller import axis_laws
from quad_msgs_bridge import kernel_cache
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
PACKAGE_DIRS = {'quad_msgs_bridge': ROOT / 'ros2_ws' / 'src' / 'quad_msgs_bridge',
                'quad_sim': ROOT / 'ros2_ws' / 'src' / 'quad_sim',
                'nnit2fsmc_controller': ROOT / 'ros2_ws' / 'src' / 'nnit2fsmc_controller',
                'flight_stack': ROOT}


def stack_sources():
    """(module name, source file) of every module of the four stack packages."""
    for package, parent in PACKAGE_DIRS.items():
        for path in sorted((parent / package).rglob('*.py')):
            parts = path.relative_to(parent).with_suffix('').parts
            yield '.'.join(parts[:-1] if parts[-1] == '__init__' else parts), path


def test_every_cached_kernel_of_the_stack_is_stamped_with_its_modules_import_closure():
    kernel_modules = [name for name, path in stack_sources() if 'cache=True' in path.read_text()]
    assert len(kernel_modules) >= 11
    kernels = 0
    for name in kernel_modules:
        module = importlib.import_module(name)
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher) and value.__module__ == name:
                assert not isinstance(value._cache, NullCache), f'{name}.{value.__name__}: not cached'
                locator = value._cache._impl.locator
                assert isinstance(locator, kernel_cache.StackSourceLocator), f'{name}.{value.__name__}'
                assert locator.get_source_stamp()[1] == kernel_cache.closure_stamp(name)
                kernels += 1
    assert kernels >= 50


def test_a_read_only_install_is_cached_in_numbas_user_wide_folder_with_the_same_stamp(tmp_path, monkeypatch):
    """Where ``__pycache__`` is not writable (an install in a system folder), numba's next choice, its
    user-wide cache folder, is taken, as numba itself would; the stamp still covers the import closure."""
    def read_only(locator):
        raise PermissionError('read-only file system')

    monkeypatch.setattr(caching.InTreeCacheLocator, 'ensure_cache_path', read_only)
    monkeypatch.setattr(caching.config, 'CACHE_DIR', '')
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    law = axis_laws.nnit2fsmc_step
    locator = kernel_cache.StackSourceLocator.from_function(law.py_func, axis_laws.__file__)
    assert Path(locator.get_cache_path()).is_relative_to(tmp_path / 'numba')
    assert locator.get_source_stamp()[1] == kernel_cache.closure_stamp('nnit2fsmc_controller.axis_laws')
    assert locator.get_disambiguator() == str(law.py_func.__code__.co_firstlineno)


def test_a_function_outside_the_stack_keeps_numbas_own_locator():
    def outside(x):
        return x

    outside.__module__ = 'some_other_package.module'
    assert kernel_cache.StackSourceLocator.from_function(outside, __file__) is None


def test_the_law_closure_holds_the_fuzzy_term_and_the_network_and_not_the_simulator_or_the_tools():
    closure = kernel_cache.import_closure('nnit2fsmc_controller.axis_laws')
    assert {'nnit2fsmc_controller.it2_fuzzy', 'nnit2fsmc_controller.neural_network', 'quad_msgs_bridge.numeric',
            'nnit2fsmc_controller', 'quad_msgs_bridge'} <= set(closure)
    assert closure['nnit2fsmc_controller.it2_fuzzy'] == PACKAGE_DIRS['nnit2fsmc_controller'].joinpath(
        'nnit2fsmc_controller', 'it2_fuzzy.py')
    assert not any(name.startswith(('quad_sim', 'flight_stack', 'quad_msgs_bridge.review', 'quad_msgs_bridge.bag'))
                   for name in closure)
    loop = kernel_cache.import_closure('flight_stack.closed_loop')
    assert {'flight_stack', 'quad_sim.model', 'nnit2fsmc_controller.axis_laws', 'nnit2fsmc_controller.controller',
            'quad_msgs_bridge.frames'} <= set(loop)


IMPORTS_IN_EVERY_FORM = '''"""A module."""
from __future__ import annotations
import numpy as np
from . import model as m
from .perturbations import (wind,   # a comment
                            actuation)
import quad_msgs_bridge.frames, nnit2fsmc_controller.it2_fuzzy as fuzzy
from quad_msgs_bridge.mixer import \\
    allocate


def late():
    from flight_stack.closed_loop import failure_code
'''


@pytest.mark.parametrize('prose', ['', 'import flight_stack.cli: a line of prose that does not parse\n'])
def test_imports_are_read_in_every_form_and_only_for_the_stack(tmp_path, prose):
    """Read line by line, or (a line that does not parse) from the whole file: the same stack modules."""
    source = tmp_path / 'fake.py'
    source.write_text(IMPORTS_IN_EVERY_FORM.replace('"""A module."""', f'"""A module.\n\n{prose}"""'))
    assert set(kernel_cache._imports_of('quad_sim.fake', source)) == {
        'quad_sim', 'quad_sim.model', 'quad_sim.perturbations', 'quad_sim.perturbations.wind',
        'quad_sim.perturbations.actuation', 'quad_msgs_bridge', 'quad_msgs_bridge.frames', 'nnit2fsmc_controller',
        'nnit2fsmc_controller.it2_fuzzy', 'quad_msgs_bridge.mixer', 'quad_msgs_bridge.mixer.allocate',
        'flight_stack', 'flight_stack.closed_loop', 'flight_stack.closed_loop.failure_code'}


def test_the_import_lines_read_alone_hold_every_import_of_every_stack_module():
    """The fast reading (each import line parsed alone) against the whole file parsed, on the real sources."""
    for name, path in stack_sources():
        source = path.read_bytes()
        exact = {ast.dump(node) for node in ast.walk(ast.parse(source))
                 if isinstance(node, (ast.Import, ast.ImportFrom))}
        fast = {ast.dump(node) for node in kernel_cache._import_statements(source, path)}
        assert exact <= fast, f'{name}: {exact - fast}'


# --- the end-to-end test: an edit of it2_fuzzy.py reaches the law that inlines it -----------------------------

LAW_CALL = '''
import json
from nnit2fsmc_controller import axis_laws
from nnit2fsmc_controller.axis_laws import NNIT2FSMCLaw
from nnit2fsmc_controller.it2_fuzzy import IT2FuzzyCorrector
from nnit2fsmc_controller.neural_network import EquivalentControlNetwork

fuzzy = IT2FuzzyCorrector(input_scale=2.0, output_gain=3.0)
law = NNIT2FSMCLaw(lam=1.5, fuzzy=fuzzy, network=EquivalentControlNetwork(3, 5, output_gain=2.0, learning_rate=0.1))
out = law.update(0.4, 0.3, 0.1, 0.0, 0.0, 1.0)
stats = axis_laws.nnit2fsmc_law_step.stats   # the kernel a single vehicle's law runs (it inlines nnit2fsmc_step)
print(json.dumps({'law': out.corrective, 'fuzzy': fuzzy(out.surface),
                  'hits': sum(stats.cache_hits.values()), 'misses': sum(stats.cache_misses.values())}))
'''

# Appended to it2_fuzzy.py: the corrective term doubled (exact in floating point), whatever its body says.
DOUBLED_FUZZY_TERM = '''

_unedited_corrective_term = corrective_term


@njit(cache=True, inline='always')
def corrective_term(parameters, s):
    return 2.0 * _unedited_corrective_term(parameters, s)
'''


def copy_of_the_packages(tree: Path) -> dict:
    """The three ROS packages copied to ``tree`` without any cache; the environment that imports them."""
    for package in ('quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller'):
        shutil.copytree(PACKAGE_DIRS[package] / package, tree / package,
                        ignore=shutil.ignore_patterns('__pycache__'))
    env = {key: value for key, value in os.environ.items() if not key.startswith('NUMBA_')}
    env['PYTHONPATH'] = str(tree)
    return env


def call_the_law(tree: Path, env: dict) -> dict:
    done = subprocess.run([sys.executable, '-c', LAW_CALL], cwd=tree, env=env, capture_output=True, text=True,
                          timeout=HANG_TIMEOUT_S)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_an_edit_of_the_fuzzy_term_reaches_the_cached_law_that_inlines_it(tmp_path):
    tree = tmp_path / 'tree'
    env = copy_of_the_packages(tree)

    first = call_the_law(tree, env)            # compiles the law and caches it
    assert first['misses'] >= 1 and first['hits'] == 0
    assert first['law'] == first['fuzzy'] != 0.0
    again = call_the_law(tree, env)            # the cached law, as any later run uses it
    assert again == {**first, 'hits': again['hits'], 'misses': 0} and again['hits'] >= 1

    unrelated = tree / 'quad_sim' / 'model.py'   # a module the law does not import: nothing recompiles
    unrelated.write_text(unrelated.read_text() + '\n# an edit\n')
    assert call_the_law(tree, env)['misses'] == 0

    fuzzy_source = tree / 'nnit2fsmc_controller' / 'it2_fuzzy.py'
    fuzzy_source.write_text(fuzzy_source.read_text() + DOUBLED_FUZZY_TERM)
    edited = call_the_law(tree, env)
    assert edited['fuzzy'] == 2.0 * first['fuzzy']
    assert edited['law'] == edited['fuzzy'], 'the law ran the cached, unedited fuzzy term'
    assert edited['misses'] >= 1
    cached_edit = call_the_law(tree, env)      # and the recompiled law is cached in its turn
    assert cached_edit['law'] == edited['law'] and cached_edit['misses'] == 0 and cached_edit['hits'] >= 1


@pytest.mark.slow
def test_an_edit_reaches_the_law_cached_in_numba_cache_dir_too(tmp_path):
    """NUMBA_CACHE_DIR set: the kernels are cached in that folder (numba's own choice), stamped alike."""
    tree = tmp_path / 'tree'
    env = copy_of_the_packages(tree)
    env['NUMBA_CACHE_DIR'] = str(tmp_path / 'numba-cache')

    first = call_the_law(tree, env)
    assert any((tmp_path / 'numba-cache').rglob('axis_laws.nnit2fsmc_law_step-*.nbi'))
    assert not any(tree.rglob('*.nbi'))
    fuzzy_source = tree / 'nnit2fsmc_controller' / 'it2_fuzzy.py'
    fuzzy_source.write_text(fuzzy_source.read_text() + DOUBLED_FUZZY_TERM)
    edited = call_the_law(tree, env)
    assert edited['law'] == edited['fuzzy'] == 2.0 * first['fuzzy']
