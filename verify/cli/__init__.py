"""The ``totems`` command: parse, call the library, map errors to exit codes.

`commands` holds the verbs and :func:`main`; `arguments` parses options' text;
`helptext` holds each verb's example and exit codes. ``python -m verify.cli`` runs it.

May import: every room of totems (it is the top).
"""

from verify.cli.commands import main

__all__ = ["main"]
