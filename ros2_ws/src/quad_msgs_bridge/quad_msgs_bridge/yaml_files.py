"""Reading the YAML files users write (vehicle files, gains files, campaign specs), with YAML 1.2 numbers.

PyYAML resolves plain scalars by YAML 1.1, where a float needs a dot and a signed exponent: ``3e-5``,
``1e30`` and ``1.0e30`` are strings there, so ``Kp: 3e-5`` would be refused as "expected a number".
:class:`YamlLoader` is PyYAML's safe loader with the YAML 1.2 (core schema) float instead: every
``[-+]? (.digits | digits[.digits]) ([eE][-+]?digits)?`` is a float (``3e-5``, ``1e30``, ``.5``,
``-1E+3``, ``1.``), as are ``.inf`` and ``.nan`` in their three spellings; YAML 1.1's forms (``1_000.5``,
sexagesimal ``1:30.0``) stay floats. Integers, booleans and everything else resolve as before.
"""
from __future__ import annotations

import re

import yaml

FLOAT_TAG = 'tag:yaml.org,2002:float'

#: a float by YAML 1.2 (core schema), plus YAML 1.1's underscores and sexagesimal floats
FLOAT_PATTERN = re.compile(r'''^(?:
    [-+]?(?:\.[0-9][0-9_]*|[0-9][0-9_]*(?:\.[0-9_]*)?)(?:[eE][-+]?[0-9]+)?
   |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
   |[-+]?\.(?:inf|Inf|INF)
   |\.(?:nan|NaN|NAN))$''', re.X)


class YamlLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` whose plain floats are YAML 1.2's (see the module doc)."""


# the integers keep their resolver, which comes first: '12' stays an int, only what it refuses can be a float
YamlLoader.yaml_implicit_resolvers = {
    first: [(tag, pattern) for tag, pattern in resolvers if tag != FLOAT_TAG]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
YamlLoader.add_implicit_resolver(FLOAT_TAG, FLOAT_PATTERN, list('-+0123456789.'))


def load_yaml(text: str):
    """The document of the YAML ``text`` (None for an empty one), read with :class:`YamlLoader`; raises
    ``yaml.YAMLError`` as ``yaml.safe_load`` does."""
    return yaml.load(text, Loader=YamlLoader)
