"""``abs`` command line: one sub-command per module in this package.

User-input errors (:class:`abs.errors.InputError`) are printed as one line naming the file and
field, with exit status 2; anything else is a bug and shows its traceback.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import abs.cli

from abs.errors import InputError

__all__ = ["main"]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="abs", description="Differentiable analysis by synthesis.")
    parser.add_argument("--variant", help="Mitsuba variant (default: $ABS_VARIANT, else CUDA if "
                                          "usable, else llvm_ad_rgb)")
    sub = parser.add_subparsers(dest="command", required=True)
    # A sub-command is a module of this package with ``add_parser``: adding one is adding a file.
    for info in sorted(pkgutil.iter_modules(abs.cli.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"abs.cli.{info.name}")
        if hasattr(module, "add_parser"):
            module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        from abs.render.variant import set_variant

        set_variant(args.variant)
        return int(args.run(args) or 0)
    except InputError as exc:
        print(f"abs {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
