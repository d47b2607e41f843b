"""Fixtures shared by the test modules."""
from __future__ import annotations

import functools
import re
import sys

import pytest


@pytest.fixture
def ros_node(request):
    """rclpy initialised for one test, and a node of the test process named after its module (e.g.
    ``test_ros_nodes``): to subscribe to what the nodes under test publish, or to publish to them."""
    import rclpy     # here, not at the top: the modules without ROS tests run where rclpy is missing
    rclpy.init()
    node = rclpy.create_node(request.module.__name__.rpartition('.')[2])
    yield node
    node.destroy_node()
    rclpy.shutdown()


#: a fixture of a test module flown once for several of its tests (a module-, package- or session-scoped fixture)
_SHARED_FIXTURE = re.compile(r"""@pytest\.fixture\([^)]*scope\s*=\s*['"](?:module|package|session)['"]""")


@pytest.hookimpl(optionalhook=True)   # a hook of pytest-xdist: without it, unused
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadgroup`` (scripts/test.sh): every test goes to whichever pytest-xdist worker is free, but the tests
    of a module with a shared fixture (a flight flown once per module) all go to one worker, which flies it once.
    (pytest-xdist 3.8's own loadgroup reads groups from the node ids, which pytest 9.2 no longer lets it change:
    pytest-dev/pytest-xdist#1386; this reads the module's source.)"""
    if config.getvalue('dist') != 'loadgroup':
        return None
    from xdist.scheduler import LoadScopeScheduling

    @functools.lru_cache(maxsize=None)
    def shares_a_fixture(path: str) -> bool:
        try:
            return bool(_SHARED_FIXTURE.search((config.rootpath / path).read_text()))
        except OSError:
            return False

    class ModuleFixtureScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split('::')[0]
            return path if shares_a_fixture(path) else nodeid

    return ModuleFixtureScheduling(config, log)


@pytest.fixture
def no_plots(monkeypatch):
    """matplotlib cannot be imported: a review writes its report without plots (faster)."""
    monkeypatch.setitem(sys.modules, 'matplotlib', None)
