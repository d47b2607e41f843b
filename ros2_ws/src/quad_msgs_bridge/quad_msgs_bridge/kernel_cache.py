"""Compiled kernels are never served stale from numba's on-disk cache.

numba (``cache=True``) stamps a cached kernel with the content of the one source file that defines it.
A kernel that inlines or calls another module's kernel has that code compiled into it, so after an edit
of the other module alone numba would go on serving the old machine code: an edit of ``it2_fuzzy.py``
changed the fuzzy term, while every NNIT2FSMC flight (``axis_laws.nnit2fsmc_step`` inlines
``it2_fuzzy.corrective_term``) stayed bit-identical until the cache files were deleted (issue 21).

Here a kernel of the stack (a function of a module of :data:`STACK_PACKAGES`) is stamped with the content
of every stack module its own module imports, directly or through other stack modules (its *import
closure*, read from the ``import`` statements of the source files). A kernel reaches another kernel only
through an import, so the closure holds every kernel it can inline or call (and the ``numeric``
overloads): an edit of any of them recompiles it, once, at its next use; an edit of any other module (the
command line, the plots) recompiles nothing.

Mechanism: :class:`StackSourceLocator` is put first in numba's list of cache locators when this module is
imported, which happens before any kernel is defined (``quad_msgs_bridge.numeric`` imports it, and every
kernel module imports ``numeric`` or this module; ``tests/test_kernel_cache.py`` checks every cached
kernel of the stack). For a stack kernel it takes the locator numba itself would have chosen (the
``NUMBA_CACHE_DIR`` folder when set, else the ``__pycache__`` beside the source, else numba's user-wide
cache folder for a read-only install) and only adds the closure's stamp to that locator's source stamp.
The cache files stay where numba puts them; a stale index is overwritten in place, so the cache does
not grow. Every other function numba caches keeps numba's own locators. (``NUMBA_CACHE_LOCATOR_CLASSES``,
when set, replaces numba's list, and this locator with it.)

Price: once per process, each stack module a kernel module reaches is read, hashed and its import lines
parsed (about 30 ms for the 27 modules a flight reaches); after an edit, the kernels that reach the edited
module compile again (docs/PAPER.md section 5 has the figures).
"""
from __future__ import annotations

import ast
import functools
import hashlib
import importlib.util
import re
import sys
from pathlib import Path

from numba.core.caching import CacheImpl, _CacheLocator

#: the top-level packages whose kernels are stamped with their import closure (they import each other)
STACK_PACKAGES = ('quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller', 'flight_stack')

_package_roots: dict[str, Path] = {}   #: top-level package -> its folder, once found


def _package_root(top: str) -> Path | None:
    """The folder of top-level package ``top``, found as an import would find it (without importing it)."""
    if top not in _package_roots:
        module = sys.modules.get(top)
        spec = module.__spec__ if module is not None else importlib.util.find_spec(top)
        if spec is None or not spec.submodule_search_locations:
            return None   # not importable now: not cached, it may become importable later (sys.path)
        _package_roots[top] = Path(list(spec.submodule_search_locations)[0])
    return _package_roots[top]


def _module_file(name: str) -> Path | None:
    """The source file of stack module ``name`` (a package's ``__init__.py``), None if there is none."""
    top, *rest = name.split('.')
    root = _package_root(top)
    if root is None:
        return None
    candidates = [root.joinpath(*rest, '__init__.py')]
    if rest:
        candidates.append(root.joinpath(*rest[:-1], rest[-1] + '.py'))
    return next((path for path in candidates if path.is_file()), None)


@functools.lru_cache(maxsize=None)
def _file_digest(path: Path) -> bytes:
    return hashlib.sha256(path.read_bytes()).digest()


#: an import statement at the start of a line, with its parenthesised or backslash-continued names
_IMPORT_STATEMENT = re.compile(rb'^[ \t]*((?:from[ \t]+[.\w]+[ \t]+)?import[ \t]+(?:\([^)]*\)|(?:[^\n\\]|\\\n)*))',
                               re.MULTILINE)


def _import_statements(source: bytes, path: Path) -> list[ast.Import | ast.ImportFrom]:
    """The import statements of a module's source, found without compiling the whole file (a tenth of the
    time): each line that starts an import is parsed alone. A line of prose that reads like an import only
    adds a module (never hides one); one that does not parse makes the whole file parsed instead."""
    statements = []
    for match in _IMPORT_STATEMENT.finditer(source):
        try:
            statements += [node for node in ast.parse(match.group(1)).body
                           if isinstance(node, (ast.Import, ast.ImportFrom))]
        except SyntaxError:
            return [node for node in ast.walk(ast.parse(source, str(path)))
                    if isinstance(node, (ast.Import, ast.ImportFrom))]
    return statements


@functools.lru_cache(maxsize=None)
def _imports_of(name: str, path: Path) -> tuple[str, ...]:
    """The stack modules that module ``name`` (source ``path``) may import, anywhere in its source, with their
    parent packages; ``from m import x`` names ``m.x`` too, which is a module when such a file exists."""
    is_package = path.name == '__init__.py'
    package = name if is_package else name.rpartition('.')[0]
    named = []
    for node in _import_statements(path.read_bytes(), path):
        if isinstance(node, ast.Import):
            named += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit('.', node.level - 1)[0] if node.level else ''
            module = '.'.join(part for part in (base, node.module) if part)
            named.append(module)
            named += [f'{module}.{alias.name}' for alias in node.names if alias.name != '*']
    modules = set()
    for dotted in named:
        parts = dotted.split('.')
        if parts[0] in STACK_PACKAGES:
            modules.update('.'.join(parts[:end]) for end in range(1, len(parts) + 1))
    return tuple(sorted(modules))


@functools.lru_cache(maxsize=None)
def import_closure(name: str) -> dict[str, Path]:
    """Stack module ``name`` and every stack module it imports, directly or through others: module -> source."""
    closure: dict[str, Path] = {}
    parts = name.split('.')
    pending = ['.'.join(parts[:end]) for end in range(1, len(parts) + 1)]   # its packages run first
    while pending:
        module = pending.pop()
        path = None if module in closure else _module_file(module)
        if path is not None:
            closure[module] = path
            pending += _imports_of(module, path)
    return closure


@functools.lru_cache(maxsize=None)
def closure_stamp(name: str) -> str:
    """A digest of the name and content of every module of :func:`import_closure` (``name``)."""
    digest = hashlib.sha256()
    for module, path in sorted(import_closure(name).items()):
        digest.update(module.encode() + b'\0' + _file_digest(path))
    return digest.hexdigest()


#: numba's own locators, in numba's order (the first that accepts a function decides where it is cached)
NUMBA_LOCATORS = tuple(CacheImpl._locator_classes)


class StackSourceLocator(_CacheLocator):
    """Where numba would cache a stack kernel, with a source stamp that covers its module's import closure."""

    def __init__(self, numba_locator: _CacheLocator, module_name: str, py_file: str):
        self._numba_locator = numba_locator
        self._py_file = py_file   # numba names it in its warnings
        self._closure_stamp = closure_stamp(module_name)

    @classmethod
    def from_function(cls, py_func, py_file):
        """A locator for a kernel of a stack module (None for any other function: numba's locators decide)."""
        module_name = getattr(py_func, '__module__', None) or ''
        if module_name.partition('.')[0] not in STACK_PACKAGES:
            return None
        for numba_class in NUMBA_LOCATORS:
            numba_locator = numba_class.from_function(py_func, py_file)
            if numba_locator is not None:
                return cls(numba_locator, module_name, py_file)
        return None

    def ensure_cache_path(self):
        self._numba_locator.ensure_cache_path()

    def get_cache_path(self):
        return self._numba_locator.get_cache_path()

    def get_disambiguator(self):
        return self._numba_locator.get_disambiguator()

    def get_source_stamp(self):
        return self._numba_locator.get_source_stamp(), self._closure_stamp


# Registered once, when this module is first imported (before any kernel of the stack is defined).
if StackSourceLocator not in CacheImpl._locator_classes:
    CacheImpl._locator_classes.insert(0, StackSourceLocator)
