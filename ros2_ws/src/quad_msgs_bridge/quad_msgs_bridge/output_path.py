"""The command-line type of an output path (``--out``): an empty one is refused, not taken as the current folder."""
from __future__ import annotations

import argparse
from pathlib import Path


def output_path(text: str) -> Path:
    """``text`` as a Path; argparse.ArgumentTypeError if it is empty (``Path('')`` is the current folder, where a
    run would scatter its files), naming what to give instead."""
    if not text.strip():
        raise argparse.ArgumentTypeError('an empty path (it would write into the current folder); give a folder, '
                                         'or . for the current one')
    return Path(text)
