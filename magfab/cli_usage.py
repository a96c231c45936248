"""click's own refusals as one line: the group class of the command line (magfab.cli and the groups it registers)."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any, NoReturn

import click

EXIT_INTERRUPTED = 130


def fail(message: str, code: int) -> NoReturn:
    """One line on stderr, ``magfab: error: <message>``, and exit ``code``."""
    click.echo(f"magfab: error: {message}", err=True)
    sys.exit(code)


class OneLineErrors(click.Group):
    """click's own errors (an unknown option, a missing argument, a bad choice: its three-line usage block) as one
    line and their exit code, as every other refusal: ``magfab: error: <what> (`<command> --help` lists what is
    allowed)``, exit 2."""

    def main(self, args: Sequence[str] | None = None, prog_name: str | None = None,
             complete_var: str | None = None, standalone_mode: bool = True, **extra: Any) -> Any:
        # (click types main() as two overloads on standalone_mode; this one takes both)
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.exceptions.NoArgsIsHelpError as exc:  # `magfab` or `magfab sensor` alone: the help, as click
            exc.show()
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            where = exc.ctx.command_path if exc.ctx is not None else "magfab"
            fail(f"{_one_line(exc.format_message())} (`{where} --help` lists what is allowed)", exc.exit_code)
        except click.ClickException as exc:
            fail(_one_line(exc.format_message()), exc.exit_code)
        except click.Abort:
            fail("interrupted; nothing was written and any previous output is untouched", EXIT_INTERRUPTED)
        sys.exit(code if isinstance(code, int) else 0)


def _one_line(text: str) -> str:
    return "; ".join(part.strip() for part in text.splitlines() if part.strip())
