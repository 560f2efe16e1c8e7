"""Output files of the subcommands: never an input, never half-written, replaced only with
--force. Shared by every subcommand that writes a file (convert, export)."""

from __future__ import annotations

import argparse
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from ..errors import InvalidInputError
from ..export.base import commit_work_file, work_file


def add_force(p: argparse.ArgumentParser, *aliases: str) -> None:
    """--force: the one flag, on every command, that lets an output replace an existing one."""
    p.add_argument("--force", *aliases, dest="force", action="store_true",
                   help="replace an existing output (never an input)")  # fmt: skip


def _same_file(a: str | Path, b: str | Path) -> bool:
    """True when a and b are one file: the same path, a hard link or a symlink to it."""
    try:
        sa, sb = os.stat(a), os.stat(b)
    except OSError:
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def _inside(path: Path, directory: str | Path) -> bool:
    try:
        return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(directory))
    except OSError:
        return False


def check_output(path: str | Path, inputs: list[str], *, force: bool, directory: bool = False) -> None:
    """Refuse, before any work, an output that cannot be written where asked (a file where a
    directory is expected or the reverse, a missing parent directory), that is (or is inside)
    an input, that is inside a store, or that exists without --force."""
    if directory:
        if os.path.exists(path) and not os.path.isdir(path):
            raise InvalidInputError(f"Output {path} is a file; give a directory.")
    else:
        if os.path.isdir(path):
            raise InvalidInputError(f"Output {path} is a directory; give a file name.")
        parent = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(parent):
            raise InvalidInputError(f"Output {path}: directory {parent} does not exist.")
    for src in inputs:
        if src == "-" or "://" in src:
            continue
        if _same_file(path, src) or (os.path.isdir(src) and _inside(Path(path), src)):
            raise InvalidInputError(f"Output {path} is the input {src} (or inside it); inputs are never written: "
                                    "choose another output.")  # fmt: skip
    # inside another store, a file would sit among its segments (or, named like one, be
    # taken by its next writer for a torn tail and deleted)
    if directory:
        refuse_store_dir(path)
    else:
        refuse_store_dir(os.path.dirname(os.path.abspath(path)), f"Output {path}: its directory")
    if os.path.lexists(path) and not force:
        raise InvalidInputError(f"Output {path} exists; pass --force to replace it, or choose another output.")


@contextmanager
def atomic_output(path: str | Path, mode: str = "w") -> Iterator:
    """A file object on a temporary name beside `path`, renamed over it only when the block
    ends without an error (so a failed or interrupted run leaves the old file, or none).
    `check_output` has refused a path that cannot take a file."""
    tmp = work_file(path)
    try:
        with open(tmp, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as f:
            yield f
        commit_work_file(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def refuse_store_dir(path: str | Path, what: str = "Output") -> None:
    """Refuse an output directory that is a store or inside one (a directory holding a
    MANIFEST): files the store does not hold would sit among its segments (`cclog fsck`
    warns of each), and a later `--force` could replace the store's own files."""
    from ..store.format import MANIFEST

    real = Path(os.path.realpath(path))
    for d in (real, *real.parents):
        if (d / MANIFEST).is_file():
            where = "" if d == real else f" (inside the store {d})"
            raise InvalidInputError(f"{what} {path} is a cclogfs store{where}; a store holds only its own "
                                    "files: choose another directory.")  # fmt: skip
