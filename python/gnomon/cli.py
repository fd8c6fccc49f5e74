"""The `gnomon` command line.

User errors (:class:`gnomon.errors.GnomonError`) print one line on stderr,
``gnomon: error: ...``, and exit with code 2. So do bad arguments (argparse).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from gnomon import __version__, _kernel
from gnomon.commands import COMMANDS
from gnomon.errors import GnomonError


def version_text() -> str:
    """``gnomon X.Y.Z (kernel X.Y.Z, SIMD avx2)``: the version and the instruction set
    the kernel's hot loops run on here (chosen at run time; see ``gnomon bench``)."""
    return f"gnomon {__version__} (kernel {_kernel.__version__}, SIMD {_kernel.simd_path()})"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gnomon",
        description="Shadow-sweep 3D scanning with a desk lamp or the sun.",
    )
    parser.add_argument("--version", action="version", version=version_text())
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        module = importlib.import_module(f"gnomon.commands.{name}")
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except GnomonError as exc:
        print(f"gnomon: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gnomon: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
