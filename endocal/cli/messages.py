"""Summary-first output on the command line: ``--explain``'s help, and the keyed lines of
:mod:`endocal.messages` every command prints.

By default a command prints its verdict, one line per warning or note and the next command; a
warning or note is then one line, ``warning[KEY]: the fact``, its key one of
:data:`endocal.messages.KEYS`, carried by the message from the moment the library made it.
``--explain`` (``-v``) prints every message in full, as the library words it.

This module imports nothing heavy: every command imports it, ``--help`` included.
"""

from __future__ import annotations

from endocal.messages import KEYS, Message, capped, head, key_of, keyed, keyed_lines

__all__ = ["EXPLAIN_HELP", "KEYS", "Message", "capped", "head", "key_of", "keyed", "keyed_lines"]

#: Help of every command's ``--explain``.
EXPLAIN_HELP = "Print the full text: every detail, and each warning and note in full (the default is a summary)."
