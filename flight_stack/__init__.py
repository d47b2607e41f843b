"""The entry script's backends: the only code that knows all three ROS packages."""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE_DIRS = [ROOT / 'ros2_ws' / 'src' / name for name in ('quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller')]

# From a fresh clone the three package folders are importable without installing them (installed with
# pip, the folders do not exist and the packages come from site-packages).
for _package_dir in PACKAGE_DIRS:
    if _package_dir.is_dir() and str(_package_dir) not in sys.path:
        sys.path.append(str(_package_dir))


def _version() -> str:
    """The stack's version: the installed distribution's, or a clone's pyproject.toml (one source either way)."""
    from importlib import metadata
    try:
        return metadata.version('nnit2fsmc-flight-stack')
    except metadata.PackageNotFoundError:
        import tomllib
        return tomllib.loads((ROOT / 'pyproject.toml').read_text())['project']['version']


__version__ = _version()
