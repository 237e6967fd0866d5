"""Standard output and error that a write failure does not stop (closed, full, a bad descriptor).

A command's work (a bag, a result folder) must not be lost because its report cannot be shown:
``Guarded`` takes the report, notes the first failure and drops the rest; ``cli.main`` then
says so in one line on the stream that still works, and exits with 1 (as ``cp``, ``ls`` and
the other GNU tools do after a write error). A closed pipe (``| head``) still ends the
command at once (``BrokenPipeError``, ``cli.main.stdout_closed``).
"""

from __future__ import annotations

import errno
import os
from typing import Any, TextIO

__all__ = ['Guarded', 'failure']


class Guarded:
    """A text stream (or None: closed when the tool started) whose write errors are noted.

    Attributes:
        error: the reason of the first write that failed, or None.
    """

    def __init__(self, stream: TextIO | None) -> None:
        self.stream = stream
        self.error: str | None = None

    def _failed(self, err: OSError) -> None:
        if self.error is None:
            self.error = os.strerror(err.errno) if err.errno else str(err)

    def write(self, text: str) -> int:
        """Write ``text``; after a failure, drop it."""
        if self.stream is None:
            if text and self.error is None:
                self.error = 'it is closed'
            return len(text)
        if self.error is not None:
            return len(text)
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            raise
        except UnicodeEncodeError:  # a stream in ASCII (PYTHONIOENCODING, a C locale)
            return self._write_escaped(text)
        except (OSError, ValueError) as err:  # ValueError: the file object was closed
            self._failed(err if isinstance(err, OSError) else OSError(errno.EBADF, str(err)))
            return len(text)

    def _write_escaped(self, text: str) -> int:
        """Write what the stream's encoding cannot hold as Python escapes (backslashreplace)."""
        assert self.stream is not None  # write() checked it
        encoding = getattr(self.stream, 'encoding', None) or 'ascii'
        escaped = text.encode(encoding, 'backslashreplace').decode(encoding)
        try:
            self.stream.write(escaped)
        except BrokenPipeError:
            raise
        except (OSError, ValueError) as err:
            self._failed(err if isinstance(err, OSError) else OSError(errno.EBADF, str(err)))
        return len(text)

    def flush(self) -> None:
        """Flush; a failure is noted."""
        if self.stream is None or self.error is not None:
            return
        try:
            self.stream.flush()
        except BrokenPipeError:
            raise
        except (OSError, ValueError) as err:
            self._failed(err if isinstance(err, OSError) else OSError(errno.EBADF, str(err)))

    def isatty(self) -> bool:
        """Whether a working terminal is behind."""
        return self.stream is not None and self.error is None and self.stream.isatty()

    def fileno(self) -> int:
        """The descriptor behind (ValueError: closed)."""
        if self.stream is None:
            raise ValueError('standard stream closed')
        return self.stream.fileno()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.stream, name)


def failure(name: str, stream: object) -> str | None:
    """'cannot write the standard output: No space left on device', or None when it worked."""
    error = stream.error if isinstance(stream, Guarded) else None
    return None if error is None else f'cannot write the standard {name}: {error}'
