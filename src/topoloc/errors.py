"""The one exception type for bad input.

Every check of a user-supplied file or config value raises :class:`InputError`
with a single-line message that names the file or the config key and says what
was expected. The workflow glue prints that line and nothing else.
"""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad user input: a file or config value that cannot be used.

    Parameters
    ----------
    where
        The offending file path or dotted config key (``graph.highway_classes``).
    message
        What is wrong and what was expected; one line.
    """

    def __init__(self, where: str | Path, message: str) -> None:
        self.where = str(where)
        self.message = " ".join(str(message).split())
        super().__init__(f"{self.where}: {self.message}")
