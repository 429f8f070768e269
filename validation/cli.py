"""The command lines' argument parser: bad input is one line and exit status 2.

:class:`ArgumentParser` is ``argparse``'s, except that a bad or missing argument prints
``<prog>: error: <what>; see <prog> --help`` (one line, no usage block) and exits 2, as every
command of the project does for bad input, and that the help keeps its text as written
(what the command does, examples, exit codes, in the ``description`` and ``epilog``).
Every command takes ``--version``: the package's version and the commit it was built from.
"""

from __future__ import annotations

import argparse
import sys

BAD_INPUT = 2


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` with one-line errors (exit 2) and help text kept as written."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action=_Version, help="print the version and the commit, and exit")

    def error(self, message: str):
        print(f"{self.prog}: error: {message}; see {self.prog} --help", file=sys.stderr)
        sys.exit(BAD_INPUT)


class _Version(argparse.Action):
    """argparse's ``version`` action, with the line made only when asked (it may ask git)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        from tactile_flow import version_line
        print(version_line(parser.prog))
        parser.exit()


def help_text(doc: str) -> str:
    """A module docstring as help text: reStructuredText's double backquotes dropped."""
    return doc.strip().replace("``", "")
