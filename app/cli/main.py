"""The `imucap` command. Each area registers its own subcommands from a module of its own
(`cli_data`, `cli_devices`, `cli_model`, ...), so the entry point stays small and the
areas do not edit one shared file."""

from __future__ import annotations

import argparse
import importlib
import sys

from drivers.extras import MissingExtra

# modules that define `register(subparsers)`; a missing one is skipped so a partial
# checkout still runs what it has
_COMMAND_MODULES = (
    "app.cli.data", "app.cli.devices", "app.cli.train", "app.cli.evaluate", "app.cli.bench", "app.cli.demo",
    "app.cli.replay", "app.cli.importing", "app.cli.advise", "app.cli.capture", "app.cli.setup", "app.cli.gui",
    "app.cli.batch", "app.cli.validate", "app.cli.report",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="imucap", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in _COMMAND_MODULES:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, OSError, MissingExtra) as exc:
        # user-facing errors (bad file, bad site name, missing device, an optional part not installed):
        # one clear line, no traceback
        print(f"imucap {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # Ctrl-C where a command does not handle it itself: the shell's 130 and one line, not a traceback
        print(f"imucap {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
